"""Pose2Sim and anipose folders as recordings: Config.toml chain, calibration search, camera matching."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest

from gttdata import ring_rig
from gttdata.calibration import save_calibration
from gttdata.cameras import CameraRig
from gttdata.errors import CalibrationError, KeypointFormatError
from gttdata.recording import CameraInput, RecordingSpec
from gttdata.recording_folders import is_recording_folder, spec_from_folder


def _rig(names):
    rig = ring_rig(len(names), rng=np.random.default_rng(0))
    return CameraRig(
        tuple(c.__class__(**{**c.__dict__, "name": n}) for c, n in zip(rig.cameras, names, strict=True))
    )


def _pose_folder(folder, n_joints=26):
    folder.mkdir(parents=True)
    doc = {"people": [{"pose_keypoints_2d": [500.0, 500.0, 0.9] * n_joints}]}
    (folder / "x_000000000000_keypoints.json").write_text(json.dumps(doc))


def _session(
    tmp_path, cal_names=("cam_01", "cam_02", "cam_03"), folders=("cam01_json", "cam02_json", "cam03_json")
):
    save_calibration(_rig(list(cal_names)), tmp_path / "calibration" / "Calib.toml") if (
        tmp_path / "calibration"
    ).mkdir() is None else None
    (tmp_path / "Config.toml").write_text('[project]\nframe_rate = 60\n[pose]\npose_model = "HALPE_26"\n')
    trial = tmp_path / "P1" / "T1"
    for f in reversed(folders):  # created out of order: matching must not depend on it
        _pose_folder(trial / "pose" / f)
    return trial


def test_config_chain_calibration_and_cameras_by_number(tmp_path):
    trial = _session(tmp_path, cal_names=("cam_03", "cam_01", "cam_02"))
    (trial / "Config.toml").write_text("[project]\nframe_rate = 50\n")  # the trial's key wins
    for path in (tmp_path, tmp_path / "P1", trial):
        assert is_recording_folder(path)
        spec = spec_from_folder(path)
        assert [(c.name, c.keypoints.name, c.fps) for c in spec.cameras] == [
            ("cam_01", "cam01_json", 50.0), ("cam_02", "cam02_json", 50.0), ("cam_03", "cam03_json", 50.0)
        ]  # fmt: skip
        assert spec.skeleton == "halpe26" and spec.calibration.name == "Calib.toml"


def test_pose_associated_preferred_over_pose(tmp_path):
    trial = _session(tmp_path)
    for f in ("cam01_json", "cam02_json", "cam03_json"):
        _pose_folder(trial / "pose-associated" / f)
    assert {c.keypoints.parent.name for c in spec_from_folder(trial).cameras} == {"pose-associated"}


def test_cameras_without_numbers_match_in_order_with_a_warning(tmp_path, caplog):
    trial = _session(tmp_path, cal_names=("left", "middle", "right"))
    with caplog.at_level(logging.WARNING, logger="gttdata.recording_folders"):
        spec = spec_from_folder(trial)
    assert [c.name for c in spec.cameras] == ["left", "middle", "right"] and "natural order" in caplog.text


def test_errors_name_the_folder(tmp_path):
    trial = _session(tmp_path, cal_names=("cam_01", "cam_02"))
    with pytest.raises(CalibrationError, match="counts differ"):
        spec_from_folder(trial)
    _pose_folder(tmp_path / "P1" / "T2" / "pose" / "cam01_json")
    with pytest.raises(KeypointFormatError, match="exactly one trial .* found 2: P1/T1, P1/T2"):
        spec_from_folder(tmp_path)
    (tmp_path / "Config.toml").write_text("[project]\nframe_rate = -3\n")
    with pytest.raises(KeypointFormatError, match="frame_rate must be a positive number or 'auto'"):
        spec_from_folder(trial)
    (tmp_path / "Config.toml").write_text('[pose]\npose_model = "BODY_99"\n')
    with pytest.raises(KeypointFormatError, match="pose_model"):
        spec_from_folder(trial)


def test_frame_rate_auto_without_videos_leaves_the_rate_to_fps(tmp_path):
    trial = _session(tmp_path)
    (tmp_path / "Config.toml").write_text('[project]\nframe_rate = "auto"\n')
    assert all(c.fps is None for c in spec_from_folder(trial).cameras)


def test_anipose_session(tmp_path):
    import tomli_w

    (tmp_path / "config.toml").write_text(tomli_w.dumps({"triangulation": {"cam_regex": "-cam([A-Z])"}}))
    session = tmp_path / "s1"
    (session / "calibration").mkdir(parents=True)
    save_calibration(_rig(["A", "B"]), session / "calibration" / "calibration.toml")
    (session / "pose-2d").mkdir()
    for cam in ("B", "A"):
        (session / "pose-2d" / f"walk-cam{cam}.csv").write_text("x")
    assert is_recording_folder(session)
    spec = spec_from_folder(session)
    assert [(c.name, c.keypoints.name) for c in spec.cameras] == [
        ("A", "walk-camA.csv"),
        ("B", "walk-camB.csv"),
    ]
    (session / "pose-2d" / "run-camA.csv").write_text("x")
    with pytest.raises(KeypointFormatError, match="2 trials"):
        spec_from_folder(session)


def test_frame_rate_auto_reads_the_videos(tmp_path):
    import cv2

    trial = _session(tmp_path)
    (tmp_path / "Config.toml").write_text('[project]\nframe_rate = "auto"\n')
    (trial / "videos").mkdir()
    for v, rate in ((1, 50.0), (2, 25.0), (3, 50.0)):
        w = cv2.VideoWriter(
            str(trial / "videos" / f"cam{v:02d}.avi"), cv2.VideoWriter_fourcc(*"MJPG"), rate, (32, 32)
        )
        for _ in range(3):
            w.write(np.zeros((32, 32, 3), np.uint8))
        w.release()
    assert [c.fps for c in spec_from_folder(trial).cameras] == [50.0, 25.0, 50.0]


def test_deeplabcut_project_skeleton_is_read_from_its_config(tmp_path):
    """A DeepLabCut file's limbs come from its project's config.yaml (read as data)."""
    import yaml

    from gttdata.detectors import Keypoints2D, write_keypoints
    from gttdata.recording import Recording

    names = ("snout", "leftear", "rightear", "tailbase")
    rig = _rig(["cam_0", "cam_1"])
    save_calibration(rig, tmp_path / "calib.toml")
    proj = tmp_path / "dlc-project"
    (proj / "videos").mkdir(parents=True)
    cfg = {"bodyparts": list(names), "skeleton": [["snout", "leftear"], ["snout", "rightear"],
                                                 ["leftear", "rightear"], ["snout", "tailbase"]]}  # fmt: skip
    (proj / "config.yaml").write_text(yaml.safe_dump(cfg))
    cams = []
    for v in range(2):
        kp = Keypoints2D(
            xy=np.full((3, 4, 2), 500.0), score=np.full((3, 4), 0.9), frame=np.arange(3), joint_names=names
        )
        write_keypoints(kp, proj / "videos" / f"cam_{v}DLC_resnet50.csv", "dlc")
        cams.append(
            CameraInput(name=f"cam_{v}", keypoints=proj / "videos" / f"cam_{v}DLC_resnet50.csv", fps=30.0)
        )
    rec = Recording.load(RecordingSpec(calibration=tmp_path / "calib.toml", cameras=tuple(cams)))
    assert rec.skeleton.joint_names == names and rec.skeleton.parents == (-1, 0, 0, 0)
    assert rec.skeleton.extra_bones == ((1, 2),)
