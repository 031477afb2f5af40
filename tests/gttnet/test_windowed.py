"""Tests of windowed reconstruction: window plans, approximate times, stitching, and the CLI option."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
from gttnet.methods import reconstruct
from gttnet.windowed import (
    approximate_times,
    auto_window,
    plan_windows,
    reconstruct_windowed,
    subset_observations,
)


@pytest.mark.parametrize(("n", "length", "overlap"), [(10, 4, 1), (100, 32, 8), (33, 32, 8), (5, 8, 2)])
def test_plan_covers_every_image_with_the_overlap(n, length, overlap):
    plan = plan_windows(np.random.default_rng(0).permutation(n).astype(float), length, overlap)
    seen = np.zeros(n, int)
    for w in range(len(plan)):
        idx = plan.window(w)
        assert idx.size == min(length, n)
        seen[idx] += 1
        wt = plan.weights(w)
        assert wt.shape == idx.shape and np.all((wt > 0) & (wt <= 1))
        if w > 0:
            shared = np.intersect1d(idx, plan.window(w - 1)).size
            assert shared >= overlap
    assert np.all(seen >= 1)
    assert np.all(np.diff(plan.starts) <= length - overlap)
    with pytest.raises(ValueError, match="overlap"):
        plan_windows(np.arange(5.0), 4, 4)


def test_approximate_times_partial_is_the_stream_fraction(scene_factory):
    obs, gt = make_view(scene_factory(n_cameras=3, frames_per_camera=10), "partial")
    t = approximate_times(obs)
    for c in range(3):
        m = obs.cam_id == c
        assert sorted(t[m].tolist()) == pytest.approx((np.arange(10) + 0.5) / 10)
        assert np.all(np.diff(t[m][np.argsort(obs.stream_index[m])]) > 0)
    # The staggered cameras of the scene are within one frame of each other on this axis.
    assert np.abs(t - (gt.timestamp_s - gt.timestamp_s.min()) / np.ptp(gt.timestamp_s)).max() < 0.12
    obs_none, _ = make_view(scene_factory(), "none")
    with pytest.raises(ValueError, match="partial"):
        approximate_times(obs_none)
    assert auto_window(obs) == (240, 60)


def test_subset_keeps_the_sequencing_layout(scene_factory):
    obs, _ = make_view(scene_factory(n_cameras=3, frames_per_camera=10), "partial")
    sub, rows = subset_observations(obs, np.array([20, 3, 11, 0, 25]))
    assert sorted(rows.tolist()) == [0, 3, 11, 20, 25]
    key = list(zip(sub.cam_id.tolist(), sub.stream_index.tolist(), strict=True))
    assert key == sorted(key)
    np.testing.assert_array_equal(sub.keypoints_px, obs.keypoints_px[rows])


@pytest.mark.parametrize("sequencing", ["full", "partial"])
def test_windowed_matches_unwindowed(scene_factory, sequencing):
    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=40, sigma_px=1.0, missing=0.1, seed=6)
    obs, gt = make_view(sample, sequencing)
    whole = reconstruct(obs, "pseudo")
    one = reconstruct_windowed(obs, "pseudo", window=obs.n_images)
    np.testing.assert_allclose(one.points3d, whole.points3d)
    rec = reconstruct_windowed(obs, "pseudo", window=48, overlap=16)
    assert rec.info["windows"] > 3 and rec.affinity is None
    assert rec.points3d.shape == whole.points3d.shape
    assert mpjpe_mm(rec.points3d, gt.points3d) < 1.1 * mpjpe_mm(whole.points3d, gt.points3d)
    assert kendall_tau(rec.order, gt.global_order) > 0.9
    assert sorted(rec.order.tolist()) == list(range(obs.n_images))


def test_auto_keeps_small_captures_in_one_piece(scene_factory):
    obs, _ = make_view(scene_factory(n_cameras=3, frames_per_camera=10), "full")
    rec = reconstruct_windowed(obs, "pseudo")
    assert "windows" not in rec.info and rec.affinity is not None


def test_cli_window_option(tmp_path, scene_factory):
    from click.testing import CliRunner

    from gttdata.shards.writer import ShardWriter
    from gttnet.cli import main

    sample = scene_factory(n_cameras=4, n_joints=6, frames_per_camera=30, sigma_px=1.0, seed=4)
    with ShardWriter(tmp_path / "shards", split="test") as w:
        w.write(sample)
    shard = sorted((tmp_path / "shards").glob("*.h5"))[0]
    args = ["reconstruct", str(shard), "--method", "pseudo", "--sequencing", "partial", "--json"]
    res = CliRunner().invoke(main, [*args, "--window", "40", "--no-progress"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["windows"] >= 3 and summary["mpjpe_mm"] < 50
    res = CliRunner().invoke(main, [*args, "--window", "off"])
    assert res.exit_code == 0 and "windows" not in json.loads(res.stdout.strip().splitlines()[-1])
    res = CliRunner().invoke(main, [*args, "--window", "x"])
    assert res.exit_code != 0 and "--window" in res.output and "Traceback" not in res.output


def test_partial_windows_follow_recovered_clocks(scene_factory):
    """A camera that started late breaks the stream-fraction guess; recovered clocks place it right."""
    from gttnet.windowed import synced_times

    sample = scene_factory(n_cameras=4, n_joints=12, frames_per_camera=60, sigma_px=1.0, seed=7)
    obs, gt = make_view(sample, "partial")
    late = (obs.cam_id == 0) & (obs.stream_index < 15)  # camera 0 misses its first 0.5 s
    obs, rows = subset_observations(obs, np.flatnonzero(~late))
    t_true = gt.timestamp_s[rows]
    frame = 1.0 / 30.0
    t_sync = synced_times(obs)
    err = (t_sync - t_sync.mean()) - (t_true - t_true.mean())
    assert np.abs(err - np.median(err)).max() < 0.25 * frame
    t_frac = approximate_times(obs) * np.ptp(t_true)
    err_frac = (t_frac - t_frac.mean()) - (t_true - t_true.mean())
    assert np.abs(err_frac - np.median(err_frac)).max() > 3 * frame  # the guess this replaces
    rec = reconstruct_windowed(obs, "pseudo", window=60, overlap=16)
    assert rec.info["clock"] == "recovered clocks"
    assert kendall_tau(rec.order, np.argsort(np.argsort(t_true))) > 0.85


def test_sync_windows_solve_on_the_recordings_clocks(scene_factory, monkeypatch):
    """Clocks are recovered once for the whole recording; every window solves on them (none re-fits)."""
    import gttnet.sync
    import gttnet.sync.method as sync_method
    from gttnet.sync import recover_clocks

    sample = scene_factory(n_cameras=4, n_joints=12, frames_per_camera=60, sigma_px=1.0, seed=7)
    obs, gt = make_view(sample, "partial")
    calls = []

    def counted(*args, **kwargs):
        calls.append(args[0].n_images)
        return recover_clocks(*args, **kwargs)

    monkeypatch.setattr(gttnet.sync, "recover_clocks", counted)
    monkeypatch.setattr(sync_method, "recover_clocks", counted)
    rec = reconstruct_windowed(obs, "sync", window=80, overlap=20, fps=30.0)
    assert calls == [obs.n_images]  # once, over the whole recording
    assert rec.info["windows"] >= 3 and rec.info["clock"] == "recovered clocks"
    assert set(rec.info["clock_offsets_s"]) == {"0", "1", "2", "3"}
    assert rec.info["cameras_left_out"] == {}
    whole = reconstruct(obs, "sync", fps=30.0)
    assert mpjpe_mm(rec.points3d, gt.points3d) < 1.1 * mpjpe_mm(whole.points3d, gt.points3d)
    calls.clear()
    auto = reconstruct_windowed(obs, "auto", window=80, overlap=20, fps=30.0)
    assert auto.info["method_ran"] == "sync"
    assert len(calls) == 2  # the recording's, and the first window's own when auto assesses sync there


def test_hpf_windows_start_their_weight_search_at_the_previous_windows(scene_factory, monkeypatch):
    """Each window after the first cross-validates HPF's weight from its neighbour's choice."""
    import dataclasses

    import gttnet.methods as methods

    spec = methods.method_spec("hpf")
    seen: list[tuple[float | None, float]] = []

    def spy(obs, **kwargs):
        rec = spec.fn(obs, **kwargs)
        seen.append((kwargs.get("lam_start"), rec.info["lam"]))
        return rec

    monkeypatch.setitem(methods._REGISTRY, "hpf", dataclasses.replace(spec, fn=spy))
    obs, gt = make_view(scene_factory(n_cameras=4, n_joints=8, frames_per_camera=60, seed=5), "full")
    rec = reconstruct_windowed(obs, "hpf", window=80, overlap=20, n_folds=3)
    assert len(seen) == rec.info["windows"] >= 3
    assert seen[0][0] is None
    assert [start for start, _ in seen[1:]] == [lam for _, lam in seen[:-1]]
    fixed = reconstruct_windowed(obs, "hpf", window=80, overlap=20, lam=seen[0][1])
    assert mpjpe_mm(rec.points3d, gt.points3d) < 1.2 * mpjpe_mm(fixed.points3d, gt.points3d)


def test_sync_with_given_clocks_skips_recovery(scene_factory, monkeypatch):
    import gttnet.sync.method as sync_method
    from gttnet.sync import recover_clocks

    obs, _ = make_view(scene_factory(n_cameras=3, n_joints=8, frames_per_camera=40, seed=2), "partial")
    clocks = recover_clocks(obs, fps=30.0)
    want = reconstruct(obs, "sync", fps=30.0)

    def fail(*args, **kwargs):
        raise AssertionError("clocks were given: nothing to recover")

    monkeypatch.setattr(sync_method, "recover_clocks", fail)
    got = reconstruct(obs, "sync", clocks=clocks)
    np.testing.assert_array_equal(got.points3d, want.points3d)
    assert got.info["clock_offsets_s"] == want.info["clock_offsets_s"]


def test_a_window_that_leaves_a_joint_nan_does_not_blank_its_neighbours(scene_factory):
    """HPF leaves a joint NaN in a window that has no ray of it; overlapping windows that do still count."""
    import dataclasses

    sample = scene_factory(n_cameras=4, n_joints=6, frames_per_camera=40, sigma_px=1.0, seed=8)
    obs, gt = make_view(sample, "full")
    vis = obs.visible.copy()
    t = obs.timestamp_s
    early = t < np.quantile(t, 0.4)
    vis[early, 2] = False  # joint 2 unseen through the first 40 % of the capture
    obs = dataclasses.replace(obs, visible=vis)
    rec = reconstruct_windowed(obs, "hpf", window=48, overlap=16, lam=10.0)
    nan = np.isnan(rec.points3d[:, 2]).any(axis=-1)
    assert nan.any() and not nan[~early].any()  # only images no window could place are NaN
    assert np.isfinite(np.delete(rec.points3d, 2, axis=1)).all()
    seen = ~nan
    assert mpjpe_mm(rec.points3d[seen][:, [2]], gt.points3d[seen][:, [2]]) < 50.0


def test_windowed_blanks_a_joint_no_image_observes(scene_factory):
    import dataclasses

    sample = scene_factory(n_cameras=4, n_joints=6, frames_per_camera=40, sigma_px=1.0, seed=9)
    obs, _ = make_view(sample, "full")
    vis = obs.visible.copy()
    vis[:, 4] = False
    rec = reconstruct_windowed(dataclasses.replace(obs, visible=vis), "pseudo", window=48, overlap=16)
    assert np.isnan(rec.points3d[:, 4]).all() and rec.info["unobserved_joints"] == [
        obs.skeleton.joint_names[4]
    ]
    assert np.isfinite(np.delete(rec.points3d, 4, axis=1)).all()
