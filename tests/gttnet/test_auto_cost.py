"""What ``auto`` spends: it stops at decisive evidence, makes each candidate once and says what it skipped."""

from __future__ import annotations

import collections
from dataclasses import replace

import numpy as np
import pytest

import gttnet.methods as methods
from gttdata.capture.views import make_view
from tests.gttnet.test_sync import _capture

RATES = {0: 25.0, 1: 30.0, 2: 60.0}
#: The real ``reconstruct``: the tests call it, the ``calls`` fixture counts the calls made inside it.
_inner = methods.reconstruct


@pytest.fixture()
def calls(monkeypatch):
    """Every ``reconstruct`` call by method name (``auto`` and ``stream-sync`` make their candidates so)."""
    count: collections.Counter = collections.Counter()
    inner = methods.reconstruct

    def counting(obs, method, **options):
        count[method] += 1
        return inner(obs, method, **options)

    monkeypatch.setattr(methods, "reconstruct", counting)
    return count


@pytest.fixture(scope="module")
def noisy():
    """At 4 px the toy motion's interpolation error is well inside the noise: timed methods are decisive."""
    return _capture((0.0, 0.4, 0.9), (30.0, 30.0, 30.0), end_s=3.0, sigma_px=4.0)


@pytest.fixture(scope="module")
def mixed():
    return _capture()  # 25, 30 and 60 Hz


def _blind(obs, cam: int):
    vis = obs.visible.copy()
    vis[obs.cam_id == cam] = False
    return replace(obs, visible=vis, keypoints_px=np.where(vis[..., None], obs.keypoints_px, np.nan))


def _skipped(rec) -> dict[str, str]:
    return {c["method"]: c["skipped"] for c in rec.info["auto"]["candidates"] if "skipped" in c}


def test_timestamps_place_a_blind_cameras_images_so_hpf_is_decisive(noisy, calls):
    """A blind camera used to block every stop: each candidate ran, DLOE included (11x HPF's time)."""
    obs = _blind(make_view(noisy, "full")[0], 1)
    rec = _inner(obs, "auto")
    assert rec.info["method_ran"] == "hpf"
    assert dict(calls) == {"hpf": 1}
    skipped = _skipped(rec)
    assert list(skipped)[0] == "sync" and list(skipped)[-1] == "dloe"
    assert all(why == "hpf's self-assessment was decisive" for why in skipped.values())


def test_a_camera_left_out_without_a_clock_does_not_make_auto_try_the_guessers(noisy, calls):
    """Each camera's frame order, one camera blind: sync leaves it out (no clock).

    GTT-Net or DLOE could only guess where its images belong, so they are not run (at 4 px the toy motion's
    interpolation error is well inside the noise: sync is decisive on the other cameras).
    """
    obs = _blind(make_view(noisy, "partial")[0], 1)
    rec = _inner(obs, "auto", fps=30.0)
    assert rec.info["method_ran"] == "sync" and "1" in rec.info["cameras_left_out"]
    assert calls["sync"] == 1 and set(calls) <= {"sync", "hpf"}  # hpf: sync's solver, where it is called so
    assert set(_skipped(rec)) >= {"dloe"}


def test_stream_sync_keeps_the_first_right_clocks_and_makes_dloe_only_if_needed(mixed, calls):
    obs, gt = make_view(mixed, "none")
    rec = _inner(obs, "stream-sync", fps=RATES)
    table = rec.info["order_sources"]
    assert rec.info["method_ran"] == "stream-sync"
    kept = rec.info["order_source"]
    assert "rms_px" in table[kept] and table[kept]["seconds"] > 0
    assert calls["dloe"] == 0 and "skipped" in table["dloe"]  # the cheap sources' clocks were right
    calls.clear()
    every = _inner(obs, "stream-sync", fps=RATES, accept_rms_noise=None)  # every source tried
    assert calls["dloe"] == 1 and all("rms_px" in v for v in every.info["order_sources"].values())
    assert every.info["order_source"] == kept


def test_auto_without_sequencing_makes_each_candidate_once_and_shares_the_order_sources(mixed, calls):
    """stream-sync used to make its own DLOE (and could not see GTT-Net's) before auto made DLOE again."""
    obs, _ = make_view(mixed, "none")
    rec = _inner(obs, "auto", fps=RATES)
    tried = rec.info["auto"]["candidates"]
    assert [c["method"] for c in tried][:2] == ["gttnet", "stream-sync"]
    assert max(calls.values()) == 1, calls  # DLOE at most once, whoever needs it first
    assert set(calls) <= {"gttnet", "stream-sync", "dloe", "pseudo", "hpf"}  # hpf: stream-sync's solver
    for c in tried:
        assert ("skipped" in c) or ("error" in c) or c["expected_error_mm"] is not None
        if "reused" in c:  # made by stream-sync for its streams: no second run
            assert c["method"] == "dloe" and c["seconds"] < 0.05


def test_stream_sync_fits_clocks_once_per_distinct_streams(mixed, calls):
    """Two sources giving the same streams (GTT-Net's order is often the pose graph's) cost one clock fit."""
    obs, _ = make_view(mixed, "none")
    d = _inner(obs, "dloe")
    given = {"dloe": d, "gttnet": replace(d, method="gttnet")}  # the same order under two names
    rec = _inner(obs, "stream-sync", fps=RATES, order_sources=("dloe", "gttnet"), order_recs=given)
    table = rec.info["order_sources"]
    assert table["gttnet"]["same_as"] == "dloe" and "rms_px" not in table["gttnet"]
    assert calls["dloe"] == 0  # given, not made again


def test_dloe_is_not_run_once_gttnet_has(calls):
    """At 2 px sync is not decisive on the toy motion, so the order-free ones are tried: GTT-Net only."""
    obs, _ = make_view(_capture((0.0, 0.4, 0.9), (30.0, 30.0, 30.0), end_s=3.0, sigma_px=2.0), "partial")
    rec = _inner(obs, "auto", fps=30.0)
    tried = [c["method"] for c in rec.info["auto"]["candidates"] if "skipped" not in c]
    assert tried == ["sync", "gttnet"] and calls["dloe"] == 0
    assert _skipped(rec) == {"dloe": "gttnet ran: dloe does not improve on it"}
    assert (
        rec.info["auto"]["why"].startswith(rec.info["method_ran"]) and "dloe" not in rec.info["auto"]["why"]
    )
