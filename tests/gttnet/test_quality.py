"""Self-assessment (gttnet.quality) and the ``auto`` selector built on it (gttnet.auto)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.capture.views import make_view
from gttnet.methods import Reconstruction, reconstruct
from gttnet.quality import assess, features, predict_mm
from tests.gttnet.test_sync import _capture


@pytest.fixture(scope="module")
def capture():
    return _capture((0.0, 0.4, 0.9), (30.0, 30.0, 30.0), end_s=3.0, sigma_px=2.0)


def _truth(obs, gt) -> Reconstruction:
    return Reconstruction(points3d=gt.points3d, order=np.argsort(np.argsort(gt.timestamp_s)))


def test_the_truth_reprojects_at_the_noise(capture):
    obs, gt = make_view(capture, "partial")
    f = features(obs, _truth(obs, gt))
    assert f["sigma_px"] == pytest.approx(2.0, abs=0.5)  # second differences along each camera's frames
    assert f["residual_px"] == pytest.approx(2.0, abs=0.25)  # the truth leaves exactly the noise
    assert f["excess"] <= 1.2 and f["holdout_ratio"] < 1.5 and f["blind_fraction"] == 0.0


def test_a_wrong_structure_raises_the_residual_and_the_prediction(capture):
    obs, gt = make_view(capture, "partial")
    good = _truth(obs, gt)
    rng = np.random.default_rng(0)
    bad = replace(good, points3d=good.points3d + rng.normal(0.0, 0.05, good.points3d.shape))  # 5 cm off
    fg, fb = features(obs, good), features(obs, bad)
    assert fb["excess"] > 3.0 and fb["excess_mm"] > 20.0
    assert predict_mm(fb) > 3.0 * predict_mm(fg)


def test_a_wrong_depth_along_the_ray_reprojects_but_fails_the_held_out_images(capture):
    """A point moved along its own ray leaves no residual in its image; the other cameras see it."""
    obs, gt = make_view(capture, "partial")
    good = _truth(obs, gt)
    C = obs.centers()[:, None, :]
    d = gt.points3d - C
    scale = 1.0 + np.random.default_rng(1).normal(0.0, 0.05, d.shape[:2])[..., None]  # ~15 cm in depth
    bad = replace(good, points3d=C + d * scale)
    fg, fb = features(obs, good), features(obs, bad)
    assert fb["residual_px"] <= fg["residual_px"] + 0.1  # the own-image residual cannot see it
    assert fb["holdout_ratio"] > 2.0 * fg["holdout_ratio"]
    assert predict_mm(fb) > 2.0 * predict_mm(fg)


def test_every_method_is_assessed_without_ground_truth(capture):
    obs, _ = make_view(capture, "none")
    rec = reconstruct(obs, "dloe")
    q = rec.info["quality"]
    assert q["expected_error_mm"] > 0 and isinstance(q["reasons"], list) and q["reasons"]
    json.dumps(q)  # JSON-serialisable as it is
    assert rec.uncertainty_mm is not None and rec.uncertainty_mm.shape == (obs.n_images, obs.n_joints)
    assert np.all(rec.uncertainty_mm[np.isfinite(rec.uncertainty_mm)] > 0)
    q2, unc = assess(obs, rec)
    assert q2 == q and np.allclose(unc, rec.uncertainty_mm, equal_nan=True)


def test_a_blind_camera_counts_where_nothing_times_its_images(capture):
    obs, _ = make_view(capture, "partial")
    vis = obs.visible.copy()
    vis[obs.cam_id == 1] = False
    kp = np.where(vis[..., None], obs.keypoints_px, np.nan)
    blind = replace(obs, visible=vis, keypoints_px=kp)
    rec = Reconstruction(points3d=np.zeros((obs.n_images, obs.n_joints, 3)) + 5.0)  # 5 m off: placeholders
    f = features(blind, rec)
    assert f["blind_fraction"] == pytest.approx(float(np.mean(obs.cam_id == 1)))
    assert features(obs, rec)["blind_fraction"] == 0.0


def _hide(obs, times, lo, hi):
    """``obs`` without any joint in the images of cameras 1 and 2 taken in ``[lo, hi)`` s (camera 0 alone)."""
    gone = (times >= lo) & (times < hi) & (obs.cam_id != 0)
    vis = obs.visible & ~gone[:, None]
    return replace(obs, visible=vis, keypoints_px=np.where(vis[..., None], obs.keypoints_px, np.nan)), gone


def test_a_stretch_seen_by_one_camera_is_weak_and_counts_in_the_prediction(capture):
    """The subject leaving two of three views: its joints there rest on the motion around the stretch."""
    obs, gt = make_view(capture, "partial")
    truth = _truth(obs, gt)
    short, _ = _hide(obs, gt.timestamp_s, 1.5, 1.7)
    long, gone = _hide(obs, gt.timestamp_s, 1.5, 2.0)
    f0, f1, f2 = features(obs, truth), features(short, truth), features(long, truth)
    # the cameras start 0.4 and 0.9 s apart: before the second starts, one camera alone sees the subject
    assert f0["weak_fraction"] == pytest.approx(np.mean(gt.timestamp_s < 0.4), abs=0.02)
    assert f0["longest_unseen_images"] == 0
    assert f0["weak_fraction"] < f1["weak_fraction"] < f2["weak_fraction"]
    assert f2["longest_unseen_images"] >= 14  # 0.5 s of a 30 Hz camera
    assert f1["weak_gap_mm"] < f2["weak_gap_mm"]  # over a longer gap the motion leaves interpolation further
    assert f2["weak_offset_mm"] < 2.0 * f2["weak_gap_mm"]  # the truth leaves interpolation as much as it can
    # A reconstruction that leaves the stretch 20 cm off: its offset shows it, the prediction follows.
    pts = truth.points3d.copy()
    pts[gone] += 0.2
    fb = features(long, replace(truth, points3d=pts))
    assert fb["weak_offset_mm"] > 150.0 and predict_mm(fb) > 1.5 * predict_mm(f2)
    q, unc = assess(long, replace(truth, points3d=pts))
    assert any("fewer than 2 cameras" in r for r in q["reasons"])
    weak = fb["weak_points"]
    assert np.nanmedian(unc[weak]) > 3.0 * np.nanmedian(unc[~weak])  # the weak points' own intervals


def test_images_of_another_person_are_contradicted_and_counted(capture):
    """A detector handing in a second person, 1 m aside, in a tenth of the images: the medians cannot see it."""
    obs, gt = make_view(capture, "partial")
    truth = _truth(obs, gt)
    t = gt.timestamp_s
    other = (obs.cam_id == 2) & (t >= 1.5) & (t < 2.4)  # about a tenth of the images
    pts = truth.points3d.copy()
    pts[other] += np.array([1.0, 0.0, 0.0])  # a method that follows the detections there
    Xc = np.einsum("nab,njb->nja", obs.cam_from_world[:, :3, :3], pts) + obs.cam_from_world[:, None, :3, 3]
    uv = np.einsum("nab,njb->nja", obs.K[:, :2, :3], Xc) / Xc[..., 2:3]
    kp = np.where(other[:, None, None], uv, obs.keypoints_px)
    crowd = replace(obs, keypoints_px=kp)
    rec = replace(truth, points3d=pts)
    f, f0 = features(crowd, rec), features(obs, truth)
    assert f0["outlier_fraction"] == 0.0
    assert f["outlier_fraction"] == pytest.approx(other.mean(), abs=0.02)
    assert (
        f["residual_px"] < 1.2 * f0["residual_px"]
    )  # the median residual does not see a tenth of the images
    true_mm = 1000.0 * float(np.mean(np.linalg.norm(pts - gt.points3d, axis=-1)))
    assert 0.5 * true_mm <= predict_mm(f) <= 2.0 * true_mm
    assert predict_mm(f0) < 0.25 * true_mm
    q, unc = assess(crowd, rec)
    assert any("contradicted by the other cameras" in r for r in q["reasons"])
    assert np.nanmedian(unc[other]) > 500.0  # their own intervals cover the metre


def test_auto_stops_at_a_decisive_candidate_and_reports_its_choice():
    """At 4 px the toy motion's interpolation error is well inside the noise: clocks explain everything."""
    obs, _ = make_view(_capture((0.0, 0.4, 0.9), (30.0, 30.0, 30.0), end_s=3.0, sigma_px=4.0), "partial")
    rec = reconstruct(obs, "auto", fps=30.0)
    a = rec.info["auto"]
    assert a["ran"] == rec.info["method_ran"] == "sync"
    ran = [c["method"] for c in a["candidates"] if "skipped" not in c]
    assert ran == ["sync"] and "decisive" in a["why"]
    assert {"method", "expected_error_mm", "seconds", "reasons"} <= set(a["candidates"][0])
    skipped = [c for c in a["candidates"] if "skipped" in c]  # the rest is listed, each with its reason
    assert [c["method"] for c in skipped][-1] == "dloe" and len(skipped) == 2
    assert all("sync's self-assessment was decisive" in c["skipped"] for c in skipped)


@pytest.mark.slow
def test_auto_tries_the_others_when_the_first_does_not_explain_the_images(capture):
    """Declared rates that are wrong: the clocks leave a residual far above the noise."""
    from gttnet.auto import candidates

    obs, gt = make_view(capture, "partial")
    rec = reconstruct(obs, "auto", fps=12.0)
    a = rec.info["auto"]
    tried = [c["method"] for c in a["candidates"]]
    assert tried == [m for m, _ in candidates(obs)]
    best = min(a["candidates"], key=lambda c: c.get("expected_error_mm", np.inf))
    assert a["ran"] == best["method"]


def test_windowed_auto_selects_on_the_first_window_then_runs_the_winner(capture):
    from gttnet.windowed import reconstruct_windowed

    obs, _ = make_view(capture, "full")
    rec = reconstruct_windowed(obs, "auto", window=120)
    assert rec.info["windows"] > 1 and rec.info["method_ran"] == rec.info["auto"]["ran"]
    assert "first window" in rec.info["auto"]["why"]


def test_reconstruct_json_has_quality_and_outputs_the_uncertainty(tmp_path):
    writer = pytest.importorskip("gttdata.shards.writer")
    from gttnet.cli import main

    with writer.ShardWriter(tmp_path / "s", split="test") as w:
        w.write(_capture((0.0, 1.3, 0.4), (30.0, 30.0, 30.0), end_s=2.5))
    shard = sorted((tmp_path / "s").glob("*.h5"))[0]
    out = tmp_path / "r.npz"
    r = CliRunner().invoke(main, ["reconstruct", str(shard), "--method", "dloe", "--json", "--out", str(out)])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output.strip().splitlines()[-1])
    assert rep["quality"]["expected_error_mm"] > 0 and rep["quality"]["reasons"]
    with np.load(out) as z:
        assert z["joint_uncertainty_mm"].shape == z["points3d"].shape[:2]
    r = CliRunner().invoke(main, ["reconstruct", str(shard), "--method", "dloe"])
    assert r.exit_code == 0 and "quality: expected error ~" in r.output


def test_hidden_error_keeps_auto_searching():
    """Medians at the noise floor are not decisive while what they cannot see makes most of the expected error."""
    from gttnet.auto import decisive

    clean = {"sigma_px": 2.0, "blind_fraction": 0.0, "excess": 1.0, "holdout_ratio": 1.0}
    clean["expected_error_mm"] = 10.0
    assert decisive(clean)
    assert decisive({**clean, "outlier_fraction": 0.01, "outlier_mm": 200.0})  # 3 of 10 mm
    assert not decisive({**clean, "outlier_fraction": 0.2, "outlier_mm": 300.0})
    weak = {**clean, "weak_fraction": 0.08, "weak_mm": 400.0}
    assert not decisive(weak)  # recovered clocks may have pulled the cameras apart
    assert decisive(weak, timed=True)  # given timestamps: the capture's own one-camera stretches
    assert decisive({**weak, "blind_fraction": 0.3, "blind_mm": 0.0})  # a camera left out: likewise
