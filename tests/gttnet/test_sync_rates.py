"""Frame rates checked or estimated from the images, blind cameras left out, order sources (gttnet.sync)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttnet.sync import recover_clocks
from gttnet.sync.rates import blind_cameras, time_warnings
from tests.gttnet.test_sync import _capture, _frame_errors


@pytest.fixture(scope="module")
def unequal():
    """Cameras at 25 / 50 / 60 Hz, started 0.2 s and 0.1 s apart."""
    cap = _capture(offsets_s=(0.0, 0.2, 0.1), fps=(25.0, 50.0, 60.0), end_s=3.0, seed=4)
    return make_view(cap, "partial")


def test_rates_are_estimated_when_none_is_given(unequal, caplog):
    obs, gt = unequal
    with caplog.at_level(logging.WARNING, logger="gttnet.sync"):
        clocks = recover_clocks(obs)  # no fps, no frame times: estimated, never a silent 30 Hz
    # Only relative rates are observable; the scale that puts every camera on a common rate is 25/50/60.
    np.testing.assert_allclose(clocks.rate_hz, [25.0, 50.0, 60.0], rtol=1e-9)
    assert np.abs(_frame_errors(obs, gt.timestamp_s, clocks)).max() < 0.1
    info = clocks.info["rates"]
    assert info["given"] is False and info["reference_camera"] == 2 and info["assumed_hz"] == 60.0
    assert any("no frame rate given" in r.getMessage() and "60 Hz" in r.getMessage() for r in caplog.records)


def test_a_wrong_given_rate_is_found_named_and_replaced(unequal, caplog):
    obs, gt = unequal
    with caplog.at_level(logging.WARNING, logger="gttnet.sync"):
        clocks = recover_clocks(obs, fps={0: 25.0, 1: 30.0, 2: 60.0})  # camera 1 really runs at 50 Hz
    np.testing.assert_allclose(clocks.rate_hz, [25.0, 50.0, 60.0], rtol=1e-9)
    assert np.abs(_frame_errors(obs, gt.timestamp_s, clocks)).max() < 0.1
    row = clocks.info["rates"]["cameras"]["1"]
    assert row["changed"] and row["given_miss_px"] > 3.0 * row["miss_px"]
    msgs = [r.getMessage() for r in caplog.records]
    assert any(m.startswith("camera 1: the given 30 Hz") and "likely 50 Hz" in m for m in msgs), msgs
    # The reference camera itself wrong: the other cameras' given rates outvote it.
    ref_wrong = recover_clocks(obs, fps={0: 25.0, 1: 50.0, 2: 30.0})
    np.testing.assert_allclose(ref_wrong.rate_hz, [25.0, 50.0, 60.0], rtol=1e-9)
    assert ref_wrong.info["rates"]["cameras"]["2"]["changed"]


def test_right_given_rates_stand_without_a_search(unequal, caplog):
    obs, _ = unequal
    with caplog.at_level(logging.WARNING, logger="gttnet.sync"):
        clocks = recover_clocks(obs, fps={0: 25.0, 1: 50.0, 2: 60.0})
    rows = clocks.info["rates"]["cameras"]
    assert not any(r["changed"] or r["searched"] for r in rows.values())
    assert not caplog.records and clocks.info["noise_px"] == pytest.approx(1.0, abs=0.3)


def _blind(obs, camera):
    """``obs`` with every joint of ``camera`` missing (all scores under the threshold, NaN scores...)."""
    from dataclasses import replace

    vis = obs.visible.copy()
    vis[obs.cam_id == camera] = False
    px = np.where(vis[..., None], obs.keypoints_px, np.nan)
    return replace(obs, visible=vis, keypoints_px=px)


def test_a_blind_camera_gets_no_clock_and_no_pose(unequal):
    from gttnet.methods import reconstruct

    obs, gt = unequal
    blind = _blind(obs, 1)
    assert set(blind_cameras(blind)) == {1} and not blind_cameras(obs)
    clocks = recover_clocks(blind, fps={0: 25.0, 1: 50.0, 2: 60.0})
    assert clocks.cameras.tolist() == [0, 2] and "no usable detection" in clocks.info["left_out"]["1"]
    rec = reconstruct(blind, "sync", fps={0: 25.0, 1: 50.0, 2: 60.0})
    cam1 = blind.cam_id == 1
    assert np.isnan(rec.points3d[cam1]).all() and np.isfinite(rec.points3d[~cam1]).all()
    assert all(rec.info["timestamp_s"][i] is None for i in np.flatnonzero(cam1))
    assert set(rec.info["cameras_left_out"]) == {"1"}
    assert sorted(rec.order.tolist()) == list(range(blind.n_images))
    assert np.all(rec.order[cam1] >= (~cam1).sum())  # ranked after every timed image
    err = np.linalg.norm(rec.points3d[~cam1] - gt.points3d[~cam1], axis=-1)
    assert 1e3 * np.nanmean(err) < 10.0
    lines = time_warnings(rec.info, {1: "side"})
    assert (
        lines[0].startswith("camera side left out of the timed solve") and "no usable detection" in lines[0]
    )


def test_clock_recovery_with_one_seeing_camera_is_refused(unequal):
    from gttnet.errors import GttNetError

    obs, _ = unequal
    with pytest.raises(GttNetError, match="two cameras with a usable stream, 1 left"):
        recover_clocks(_blind(_blind(obs, 1), 2))


def test_root_rank_orders_a_walk_whose_poses_repeat():
    from gttnet.sync.streams import root_rank

    t = np.linspace(0.0, 4.0, 200)
    rng = np.random.default_rng(0)
    limbs = np.sin(2.0 * np.pi * 1.5 * t)[:, None, None] * rng.normal(size=(1, 8, 3)) * 0.3  # a cycle
    x = limbs + np.stack([1.2 * t, 0.1 * np.sin(t), np.zeros_like(t)], axis=-1)[:, None, :]
    perm = rng.permutation(t.size)
    rank = root_rank(x[perm])
    in_time = perm[np.argsort(rank)]  # the true time index of the images, in the recovered order
    assert np.all(np.diff(in_time) > 0) or np.all(np.diff(in_time) < 0)


def test_auto_with_one_camera_declared_at_a_wrong_rate_warns_naming_it(unequal, caplog):
    """One camera's declared rate wrong, the others right: ``auto`` names it and its likely rate.

    Its result is as good as with the right rates (not silently worse).
    """
    from gttnet.evaluate.metrics import mpjpe_mm
    from gttnet.methods import reconstruct

    obs, gt = unequal
    right = reconstruct(obs, "auto", fps={0: 25.0, 1: 50.0, 2: 60.0})
    with caplog.at_level(logging.WARNING, logger="gttnet.sync"):
        rec = reconstruct(obs, "auto", fps={0: 25.0, 1: 30.0, 2: 60.0})  # camera 1 really runs at 50 Hz
    msgs = [r.getMessage() for r in caplog.records]
    assert any(m.startswith("camera 1: the given 30 Hz") and "likely 50 Hz" in m for m in msgs), msgs
    assert not any(m.startswith(("camera 0", "camera 2")) for m in msgs), msgs
    assert mpjpe_mm(rec.points3d, gt.points3d) <= 1.2 * mpjpe_mm(right.points3d, gt.points3d)
    assert rec.info["quality"]["expected_error_mm"] <= 2.0 * right.info["quality"]["expected_error_mm"]
