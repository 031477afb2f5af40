"""Recordings: export -> project file -> Observations equal the shard's view; timing; one-line errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttdata.errors import CalibrationError, GttDataError, KeypointFormatError
from gttdata.export import export_capture
from gttdata.recording import CameraInput, Recording, ground_truth_for, load_project


@pytest.fixture
def sample(scene_factory):
    return scene_factory(n_cameras=3, n_joints=5, frames_per_camera=8, sigma_px=1.0, missing=0.2, seed=3)


@pytest.mark.parametrize("fmt, units", [("openpose", "mm"), ("dlc", "m")])
def test_export_round_trip_equals_shard_view(tmp_path, sample, fmt, units):
    proj = export_capture(sample, tmp_path / "rec", fmt=fmt, units=units)
    spec = load_project(proj)
    rec = Recording.load(spec)
    assert rec.camera_names == ("cam_0", "cam_1", "cam_2") and rec.calibration_units == units
    view = rec.view()
    obs, gt = make_view(sample, "partial")
    got = view.observations
    assert got.sequencing == "partial"
    np.testing.assert_array_equal(got.cam_id, obs.cam_id)
    np.testing.assert_array_equal(got.stream_index, obs.stream_index)
    np.testing.assert_array_equal(got.visible, obs.visible)
    np.testing.assert_array_equal(got.keypoints_px, obs.keypoints_px.astype(np.float64))
    np.testing.assert_allclose(got.cam_from_world, obs.cam_from_world, atol=1e-12)
    assert got.confidence.min() >= 0 and np.all(got.confidence[got.visible] >= 0.15)
    # Each camera's own clock: its first frame at 0, spacing as captured.
    for v in range(3):
        rows = obs.cam_id == v
        np.testing.assert_allclose(
            got.stream_time_s[rows], gt.timestamp_s[rows] - gt.timestamp_s[rows][0], atol=1e-9
        )
    np.testing.assert_array_equal(ground_truth_for(view, spec.ground_truth), gt.points3d)


def test_shared_clock_gives_full_sequencing(tmp_path, sample):
    spec = load_project(export_capture(sample, tmp_path / "rec", shared_clock=True))
    view = Recording.load(spec).view()
    obs, _ = make_view(sample, "full")
    assert view.observations.sequencing == "full"
    np.testing.assert_allclose(view.observations.timestamp_s, obs.timestamp_s, atol=1e-9)
    np.testing.assert_array_equal(view.observations.cam_id, obs.cam_id)


def test_fps_timing_and_threshold(tmp_path, sample):
    spec = load_project(export_capture(sample, tmp_path / "rec"))
    spec = dataclasses.replace(
        spec, cameras=tuple(dataclasses.replace(c, timestamps=None, fps=30.0) for c in spec.cameras)
    )
    rec = Recording.load(spec)
    view = rec.view(min_confidence=0.9)
    obs = view.observations
    np.testing.assert_allclose(obs.stream_time_s, obs.stream_index / 30.0)
    assert (
        np.all(obs.confidence[obs.visible] >= 0.9)
        and obs.visible.sum() < rec.view().observations.visible.sum()
    )
    np.testing.assert_array_equal(rec.fps, [30.0] * 3)


def test_errors_name_file_and_field(tmp_path, sample):
    proj = export_capture(sample, tmp_path / "rec")
    spec = load_project(proj)
    renamed = dataclasses.replace(spec.cameras[1], name="camB")
    with pytest.raises(
        CalibrationError, match=r"rec/cam_1: camera 'camB' is not in calibration .*cam_0, cam_1, cam_2"
    ):
        Recording.load(dataclasses.replace(spec, cameras=(spec.cameras[0], renamed)))
    gone = CameraInput(name="cam_2", keypoints=tmp_path / "rec" / "nope")
    with pytest.raises(FileNotFoundError):
        Recording.load(dataclasses.replace(spec, cameras=(spec.cameras[0], gone)))
    ts = spec.cameras[0].timestamps
    ts.write_text("".join(ts.read_text().splitlines(keepends=True)[:4]))
    with pytest.raises(
        KeypointFormatError, match=r"cam_0_timestamps.csv: has 4 frame times but .*cam_0 has frame 7"
    ):
        Recording.load(spec)
    with pytest.raises(GttDataError, match="not empty; pass --overwrite"):
        export_capture(sample, tmp_path / "rec")
    (tmp_path / "p.toml").write_text('calibration = "c.toml"\n')
    with pytest.raises(KeypointFormatError, match=r"p.toml: field 'cameras' is missing"):
        load_project(tmp_path / "p.toml")


def test_yaml_project(tmp_path, sample):
    export_capture(sample, tmp_path / "rec", fmt="dlc")
    (tmp_path / "rec" / "p.yaml").write_text(
        "calibration: calibration.toml\nclock: per-camera\ncameras:\n"
        + "".join(f"  - {{name: cam_{v}, keypoints: cam_{v}.csv, fps: 30}}\n" for v in range(3))
    )
    view = Recording.load(load_project(tmp_path / "rec" / "p.yaml")).view()
    assert view.observations.n_images == sample.n_images and view.observations.sequencing == "partial"


def test_detector_keypoint_set_maps_onto_its_skeleton(tmp_path, scene_factory):
    from gttdata.skeletons import get_skeleton

    seventeen = scene_factory(n_cameras=3, n_joints=17, frames_per_camera=4, seed=1)
    spec = load_project(export_capture(seventeen, tmp_path / "rec", fmt="openpose"))
    rec = Recording.load(dataclasses.replace(spec, skeleton=None))  # OpenPose files name no joints
    assert rec.skeleton == get_skeleton("coco17") and len(rec.skeleton.bones) >= 16
    with pytest.raises(
        KeypointFormatError, match="skeleton 'body25' has 25 joints but the keypoint sources have 17"
    ):
        Recording.load(dataclasses.replace(spec, skeleton="body25"))


def _empty_openpose(folder) -> None:
    """Rewrite every OpenPose file of a camera folder with no person in it."""
    import json

    for f in folder.glob("*.json"):
        doc = json.loads(f.read_text())
        doc["people"] = []
        f.write_text(json.dumps(doc))


def test_a_camera_that_never_saw_anyone_is_left_out(tmp_path, sample, caplog):
    spec = load_project(export_capture(sample, tmp_path / "rec", fmt="openpose"))
    _empty_openpose(tmp_path / "rec" / "cam_1")
    with caplog.at_level("WARNING", logger="gttdata.recording"):
        rec = Recording.load(spec)
    assert rec.camera_names == ("cam_0", "cam_2")
    assert "cam_1: no person detected in any of the 8 files; camera 'cam_1' left out" in caplog.text
    view = rec.view()
    obs, gt = make_view(sample, "partial")
    kept = obs.cam_id != 1
    np.testing.assert_array_equal(view.observations.keypoints_px, obs.keypoints_px[kept].astype(np.float64))
    np.testing.assert_array_equal(ground_truth_for(view, spec.ground_truth), gt.points3d[kept])


def test_no_camera_with_a_detection_is_one_line(tmp_path, sample):
    from gttdata.errors import NoDetectionsError

    spec = load_project(export_capture(sample, tmp_path / "rec", fmt="openpose"))
    for v in range(3):
        _empty_openpose(tmp_path / "rec" / f"cam_{v}")
    with pytest.raises(
        NoDetectionsError, match=r"^no camera has a detection: .*cam_0: no person detected .* \(and 2 more\)$"
    ):
        Recording.load(spec)
