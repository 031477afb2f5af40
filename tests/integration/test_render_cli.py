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


def test_render_needs_a_recording_result(tmp_path, scene_factory):
    from gttdata.shards.writer import ShardWriter

    with ShardWriter(tmp_path / "s", split="test") as w:
        w.write(scene_factory(n_cameras=3, n_joints=5, frames_per_camera=4))
    shard = sorted((tmp_path / "s").glob("*.h5"))[0]
    res = CliRunner().invoke(
        main, ["reconstruct", str(shard), "--method", "pseudo", "--out", str(tmp_path / "r.h5")]
    )
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["render", str(tmp_path / "r.h5")])
    assert res.exit_code == 1 and "field 'recording' is missing" in res.output
