"""``gttnet render``: overlay videos with per-joint reprojection error, timing plot, distortion-aware projection."""

from __future__ import annotations

import csv
import dataclasses
import json

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from gttdata import ring_rig
from gttdata.calibration import distort_points
from gttdata.export import export_capture
from gttnet.apps.render import project_with_distortion
from gttnet.cli import main
from gttnet.io.output import read_reconstruction

pytestmark = pytest.mark.integration


def test_projection_goes_through_the_lens():
    cam = dataclasses.replace(ring_rig(1)[0], dist=(-0.3, 0.02, 0.001, 0.0, 0.0))
    X = np.random.default_rng(0).uniform([-0.5, -0.5, 0.2], [0.5, 0.5, 1.6], (20, 3))
    px, _ = cam.project(X)
    np.testing.assert_allclose(project_with_distortion(X, cam), distort_points(px, cam), atol=1e-9)


def test_render_writes_videos_and_errors(scene_factory, tmp_path):
    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=2.0, seed=2)
    project = export_capture(sample, tmp_path / "rec", shared_clock=True)
    result = tmp_path / "r.h5"
    res = CliRunner().invoke(main, ["reconstruct", str(project), "--method", "hpf", "--out", str(result)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "render"
    res = CliRunner().invoke(main, ["render", str(result), "--out", str(out), "--no-3d", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert {"cam_0.mp4", "cam_1.mp4", "cam_2.mp4", "timing.png", "reprojection_error.csv"} <= set(
        summary["files"]
    )
    for v in range(3):
        cap = cv2.VideoCapture(str(out / f"cam_{v}.mp4"))
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 6
    # The reported error is the distance between each detection and its row's projection (pinhole here).
    arrays, _ = read_reconstruction(result)
    rig = ring_rig(3)
    errs = []
    for n in range(arrays["points3d"].shape[0]):
        v, f = int(arrays["cam_id"][n]), int(arrays["frame"][n])
        k = np.flatnonzero((sample.cam_id == v) & (sample.stream_index == f))[0]
        px, _ = rig[v].project(arrays["points3d"][n])
        e = np.linalg.norm(px - sample.keypoints_px[k], axis=-1)
        errs.append(e[sample.visible[k]])
    expected = float(np.concatenate(errs).mean())
    assert expected > 0.1  # hpf smooths: the projections do not sit on the detections
    assert summary["reprojection_mean_px"] == pytest.approx(expected, abs=2e-3)
    with open(out / "reprojection_error.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 * 5 and all(float(r["mean_px"]) >= 0 for r in rows if r["mean_px"])


def test_render_of_a_capture_result_reprojects_through_each_image(tmp_path, scene_factory):
    """A result made from a shard (no recording) gets the reprojection table and the timing plot."""
    from gttdata.shards.writer import ShardWriter
    from gttnet.io import load_input

    with ShardWriter(tmp_path / "s", split="test") as w:
        w.write(scene_factory(n_cameras=3, n_joints=5, frames_per_camera=4, sigma_px=2.0))
    shard = sorted((tmp_path / "s").glob("*.h5"))[0]
    result = tmp_path / "r.h5"
    res = CliRunner().invoke(main, ["reconstruct", str(shard), "--method", "hpf", "--out", str(result)])
    assert res.exit_code == 0, res.output
    out = tmp_path / "render"
    res = CliRunner().invoke(main, ["render", str(result), "--out", str(out), "--no-3d", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert set(summary["files"]) == {"reprojection_error.csv", "timing.png"}
    # Independently: each row's joints through its own image's K and pose, against that image's pixels.
    arrays, _ = read_reconstruction(result)
    obs = load_input(shard, sequencing="partial").observations
    view_row = {int(k): i for i, k in enumerate(load_input(shard, sequencing="partial").image_index)}
    errs = []
    for n, k in enumerate(arrays["image_index"]):
        i = view_row[int(k)]
        Xc = arrays["points3d"][n] @ obs.cam_from_world[i, :3, :3].T + obs.cam_from_world[i, :3, 3]
        h = Xc @ obs.K[i].T
        e = np.linalg.norm(h[:, :2] / h[:, 2:] - obs.keypoints_px[i], axis=-1)
        errs.append(e[obs.visible[i]])
    expected = float(np.concatenate(errs).mean())
    assert expected > 0.1  # hpf smooths: the projections leave the noisy detections
    assert summary["reprojection_mean_px"] == pytest.approx(expected, abs=2e-3)


def test_render_of_a_capture_result_names_a_missing_or_mismatched_input(tmp_path):
    from gttnet.io.gttnet_json import write_gttnet_json
    from tests.gttnet.test_authors_json import _sample

    cap = write_gttnet_json(_sample("coco17"), tmp_path / "cap.json")
    result = tmp_path / "r.h5"
    res = CliRunner().invoke(
        main, ["reconstruct", str(cap), "--method", "pseudo", "--sequencing", "none", "--out", str(result)]
    )
    assert res.exit_code == 0, res.output
    moved = tmp_path / "elsewhere.json"
    cap.rename(moved)
    res = CliRunner().invoke(main, ["render", str(result), "--no-3d", "--out", str(tmp_path / "a")])
    assert res.exit_code == 1 and "was not found; pass the input file (--input)" in res.output
    assert "Traceback" not in res.output
    res = CliRunner().invoke(
        main, ["render", str(result), "--no-3d", "--input", str(moved), "--out", str(tmp_path / "b")]
    )
    assert res.exit_code == 0, res.output
    other = write_gttnet_json(_sample("quadruped36"), tmp_path / "other.json")
    res = CliRunner().invoke(
        main, ["render", str(result), "--no-3d", "--input", str(other), "--out", str(tmp_path / "c")]
    )
    assert res.exit_code == 1 and "do not match" in res.output and len(res.output.strip().splitlines()) == 1


def test_animation_draws_every_row_unless_told_and_says_when_it_subsamples(tmp_path, caplog):
    from gttdata.errors import RendererUnavailableError
    from gttnet.apps import render as render_mod

    calls = []

    def fake_render_view(points, skeleton, K, T, size, **kw):  # stands in for pyrender: counts frames
        calls.append(1)
        return np.zeros((size[1], size[0], 3), np.uint8)

    import gttdata.preview.render as pr

    orig = pr.render_view
    pr.render_view = fake_render_view
    try:
        from tests.gttnet.test_authors_json import _sample

        sample = _sample("coco17")
        X = sample.points3d
        order = np.arange(X.shape[0])
        render_mod._animation(tmp_path / "a.mp4", X, order, sample.skeleton, 10.0, None)
        assert len(calls) == X.shape[0]  # every row: no silent 300-frame cap
        calls.clear()
        with caplog.at_level("WARNING"):
            render_mod._animation(tmp_path / "b.mp4", X, order, sample.skeleton, 10.0, 5)
        assert len(calls) <= 5 and "faster than the capture" in caplog.text
    except RendererUnavailableError:
        pytest.skip("no OpenGL")
    finally:
        pr.render_view = orig
