"""Event segmentation: ARI, components vs spectral clusters, per-event order, and a tiny events capture."""

from __future__ import annotations

import numpy as np
import pytest

from gttnet.apps.segment import (
    adjusted_rand_index,
    estimate_n_clusters,
    score_segmentation,
    segment_capture,
    segment_events,
)


def _chains(sizes, link=0.0, seed=0):
    """Affinity of disjoint chains (one per event), images shuffled; ``link`` joins consecutive chains."""
    n = sum(sizes)
    A = np.zeros((n, n))
    start = 0
    for s in sizes:
        i = np.arange(start, start + s - 1)
        A[i, i + 1] = A[i + 1, i] = 1.0
        if link and start:
            A[start - 1, start] = A[start, start - 1] = link
        start += s
    event = np.repeat(np.arange(len(sizes)), sizes)
    perm = np.random.default_rng(seed).permutation(n)
    return A[np.ix_(perm, perm)], event[perm], np.arange(n)[perm]


def test_ari_known_values():
    assert adjusted_rand_index([0, 0, 1, 1], [1, 1, 0, 0]) == 1.0
    assert adjusted_rand_index([0, 0, 1, 1], [0, 0, 1, 2]) == pytest.approx(0.5714285714285715)
    assert adjusted_rand_index([0, 0, 0, 0], [0, 0, 0, 0]) == 1.0
    rng = np.random.default_rng(0)
    assert abs(adjusted_rand_index(rng.integers(0, 3, 3000), rng.integers(0, 3, 3000))) < 0.02
    with pytest.raises(ValueError, match="same shape"):
        adjusted_rand_index([0, 1], [0])


def test_disjoint_chains_are_components_with_exact_order():
    A, event, time = _chains([30, 20, 25])
    seg = segment_events(A)
    assert seg.how == "components" and seg.n_events == 3
    sc = score_segmentation(seg, event, time)
    assert sc["ari"] == 1.0 and sc["tau_mean"] == pytest.approx(1.0)


def test_weakly_linked_chains_need_spectral_clusters():
    A, event, time = _chains([40, 40], link=0.01)
    assert estimate_n_clusters(A) == 2
    seg = segment_events(A)
    assert seg.how == "spectral" and adjusted_rand_index(event, seg.labels) == 1.0
    # a stronger link hides the gap from the estimate (a chain's own spectrum grows like k^2), but a
    # known event count still splits it
    A, event, _ = _chains([40, 40], link=0.05)
    assert adjusted_rand_index(event, segment_events(A, n_events=2).labels) == 1.0
    seg3 = segment_events(_chains([30, 30, 30], link=0.05)[0], n_events=3)
    assert seg3.n_events == 3


def test_one_chain_is_one_event():
    A, _, _ = _chains([80])
    assert segment_events(A).n_events == 1


def test_tiny_events_capture_ari_one():
    from gttdata.capture.views import make_view
    from gttdata.generate_plan import build_sample
    from gttdata.recipe import load_recipe

    recipe = load_recipe(
        "recipes/gttdata/events.yaml",
        [
            "rig.n_cameras=4",
            "capture.fps_hz=10",
            "capture.window_s=1.0",
            "capture.sigma_px=0",
            "scene.n_events=2",
            "scene.event_gap_s=1.0",
            # Well-separated events by construction (a run and a jog would share poses).
            "splits.test.sources.0.kinds=[gesture, run]",
        ],
    )
    sample = build_sample(recipe, "test", 0)[0]
    assert sorted(m["name"].split("/")[1] for m in sample.meta["motions"]) == ["gesture", "run"]
    obs, gt = make_view(sample, "none")
    rec, seg = segment_capture(obs, method="dloe")
    event = np.asarray(sample.meta["event_id"])[gt.perm]
    sc = score_segmentation(seg, event, gt.global_order)
    assert sc["n_events"] == 2 and sc["ari"] == 1.0
    assert sc["tau_mean"] > 0.7


def test_method_without_affinity_is_refused(monkeypatch):
    import gttnet.methods as reg

    class _Rec:
        affinity = None

    monkeypatch.setattr(reg, "reconstruct", lambda obs, method, **o: _Rec())
    with pytest.raises(ValueError, match="no affinity"):
        segment_capture(object(), method="x")


@pytest.mark.parametrize(
    "method, given, expected", [("gttnet", {}, False), ("gttnet", {"refine": True}, True)]
)
def test_segment_uses_gttnets_learned_affinity_unless_asked(monkeypatch, method, given, expected):
    import gttnet.methods
    from gttnet.apps.segment import segment_capture
    from gttnet.methods import Reconstruction

    seen = {}

    def fake(obs, name, **options):
        seen.update(options)
        a, _, _ = _chains([6, 6])
        return Reconstruction(points3d=np.zeros((12, 2, 3)), affinity=a)

    monkeypatch.setattr(gttnet.methods, "reconstruct", fake)
    segment_capture(object(), method=method, **given)
    assert seen["refine"] is expected
