"""Order-free captures of a fast motion at a low frame rate: the pseudo-triangulation partner graph's order.

A procedural quadruped turning, filmed by 4 cameras at 10 Hz for 8 s (320 images, 1 px noise): whole poses
are a poor guide to time there (the pose graph and DLOE order each camera's frames wrongly), while the
images that triangulate well together are still the ones of the same moment. Before the partner graph
became an order source, ``stream-sync`` kept DLOE's order and its clocks (283 mm, against 4 mm now), and
the cross-domain GTT-Net's camera streams came from the pose graph (18.8 mm, worse than DLOE; 7.6 mm now).
Ground truth scores the results only.
"""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe
from gttnet.methods import reconstruct
from gttnet.sync.streams import ORDER_SOURCES

RECIPE = "recipes/gttdata/heldout.yaml"


@pytest.fixture(scope="module")
def fast_capture():
    recipe = load_recipe(RECIPE, ["capture.fps_hz=10", "capture.window_s=8", "capture.sigma_px=1.0"])
    sample = build_sample(recipe, "test_quadruped", 0)[0]
    return make_view(sample, "none")


def _mpjpe_mm(rec, gt) -> float:
    return float(1000.0 * np.nanmean(np.linalg.norm(rec.points3d - gt.points3d, axis=-1)))


def test_partner_graph_is_an_order_source():
    assert "pseudo" in ORDER_SOURCES


def test_stream_sync_keeps_the_partner_graph_order(fast_capture):
    obs, gt = fast_capture
    assert obs.n_images == 320
    rec = reconstruct(obs, "stream-sync", fallback=None)
    assert rec.info["order_source"] == "pseudo"
    # every other source's clocks explain the images worse than the kept ones
    table = rec.info["order_sources"]
    kept = table["pseudo"]["rms_px"]
    assert all(v.get("rms_px") is None or v["rms_px"] >= kept for v in table.values())
    assert _mpjpe_mm(rec, gt) < 10.0


def test_cross_domain_gttnet_streams_beat_dloe(fast_capture):
    obs, gt = fast_capture
    net = _mpjpe_mm(reconstruct(obs, "gttnet"), gt)
    dloe = _mpjpe_mm(reconstruct(obs, "dloe"), gt)
    assert net < dloe, (net, dloe)


def test_auto_reads_every_candidate_along_the_best_ordered_streams(fast_capture):
    """Auto re-reads a candidate's evidence along the streams with the least noise.

    GTT-Net's own order reads ~38 px of noise here (1.6 px along the kept streams): its expected error was
    ~250 mm for a 7.6 mm result, and a wrong pick followed on other captures. Re-read, its expected error
    is within [0.5x, 2x] of the truth.
    """
    obs, gt = fast_capture
    rec = reconstruct(obs, "auto")
    rows = {c["method"]: c for c in rec.info["auto"]["candidates"]}
    net = rows["gttnet"]
    assert any(r.startswith("read along") for r in net["reasons"]), net["reasons"]
    true_net = _mpjpe_mm(reconstruct(obs, "gttnet"), gt)
    assert 0.5 * true_net <= net["expected_error_mm"] <= 2.0 * true_net, (net["expected_error_mm"], true_net)
    assert _mpjpe_mm(rec, gt) <= 1.1 * min(true_net, _mpjpe_mm(reconstruct(obs, "dloe"), gt))
