"""Tests of sequencing-aware neighbourhoods and the chain affinities."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gttdata.capture.views import make_view
from gttnet.errors import SequencingError
from gttnet.geometry.neighbours import (
    chain_affinity,
    neighbourhoods,
    temporal_chain_affinity,
    temporal_interpolation_affinity,
)
from gttnet.geometry.triangulation import pseudo_triangulate

INF = np.inf


def test_none_ranks_other_cameras_by_cost_and_pads():
    cam = np.array([0, 1, 1, 2])
    cost = np.array([[INF, 3.0, 1.0, 2.0], [3.0, INF, INF, INF], [1.0, INF, INF, 0.5], [2.0, INF, 0.5, INF]])
    nb = neighbourhoods(cost, sequencing="none", cam_id=cam, k=3)
    assert nb.tolist() == [[2, 3, 1], [0, -1, -1], [3, 0, -1], [2, 0, -1]]
    assert nb.dtype == np.int64


def test_partial_keeps_one_contiguous_run_per_stream():
    # Image 0 (camera 0) against camera 1's stream of 4 images (stream indices 0..3, stored shuffled).
    # Stream index 3 looks good (repeated pose) but is not adjacent to the best run: it is dropped.
    cam = np.array([0, 1, 1, 1, 1])
    si = np.array([0, 2, 0, 3, 1])
    cost = np.full((5, 5), INF)
    cost[0, 1:] = cost[1:, 0] = [
        9.0,
        1.0,
        2.0,
        5.0,
    ]  # by stream index: 0 -> 1.0, 1 -> 5.0, 2 -> 9.0, 3 -> 2.0
    nb = neighbourhoods(cost, sequencing="partial", cam_id=cam, stream_index=si, k=3)
    assert nb[0].tolist() == [2, 4, 1]
    none = neighbourhoods(cost, sequencing="none", cam_id=cam, k=3)
    assert none[0].tolist() == [2, 3, 4]


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 12))
def test_partial_runs_are_contiguous_and_other_stream(seed, k):
    g = np.random.default_rng(seed)
    cam = g.integers(0, 3, size=30)
    si = np.zeros(30, dtype=int)
    for c in range(3):
        idx = np.nonzero(cam == c)[0]
        si[idx] = g.permutation(idx.size)
    cost = g.uniform(size=(30, 30))
    cost = cost + cost.T
    cost[cam[:, None] == cam[None, :]] = INF
    nb = neighbourhoods(cost, sequencing="partial", cam_id=cam, stream_index=si, k=k)
    for i in range(30):
        row = nb[i][nb[i] >= 0]
        assert len(set(row.tolist())) == row.size
        assert np.all(cam[row] != cam[i])
        for c in np.unique(cam[row]):
            s = np.sort(si[row[cam[row] == c]])
            assert np.all(np.diff(s) == 1)
        assert row.size == min(k, int(np.sum(cam != cam[i])))


def _partial_reference(cost, cam, si, k):
    """The rule as written in neighbourhoods' docstring, one row at a time with a priority queue."""
    import heapq

    n = cam.size
    ok = np.isfinite(cost) & (cam[:, None] != cam[None, :])
    rank = np.argsort(np.argsort(cost, axis=1, kind="stable"), axis=1)
    pos = {}
    for c in np.unique(cam):
        m = np.flatnonzero(cam == c)
        pos[c] = m[np.argsort(si[m], kind="stable")].tolist()
    out = np.full((n, k), -1)
    for i in range(n):
        heap = []
        for c, stream in pos.items():
            allowed = [j for j in stream if ok[i, j]]
            if c != cam[i] and allowed:
                best = min(allowed, key=lambda j: rank[i, j])
                heap.append((rank[i, best], best))
        heapq.heapify(heap)
        seen = {j for _, j in heap}
        taken = []
        while heap and len(taken) < k:
            _, j = heapq.heappop(heap)
            taken.append(j)
            stream = pos[cam[j]]
            p = stream.index(j)
            for q in (p - 1, p + 1):
                if 0 <= q < len(stream) and ok[i, stream[q]] and stream[q] not in seen:
                    seen.add(stream[q])
                    heapq.heappush(heap, (rank[i, stream[q]], stream[q]))
        out[i, : len(taken)] = taken
    return out


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 12), st.integers(2, 5), st.floats(0.0, 0.5))
def test_partial_matches_priority_queue_reference(seed, k, n_cams, p_inf):
    # The vectorised growth takes the same images in the same order as the one-row priority queue, with
    # non-finite pairs (missing joints) breaking runs.
    g = np.random.default_rng(seed)
    n = 24
    cam = g.integers(0, n_cams, size=n)
    si = np.zeros(n, dtype=int)
    for c in range(n_cams):
        idx = np.nonzero(cam == c)[0]
        si[idx] = g.permutation(idx.size)
    cost = g.uniform(size=(n, n))
    cost = cost + cost.T
    cost[g.uniform(size=(n, n)) < p_inf] = INF
    cost[cam[:, None] == cam[None, :]] = INF
    nb = neighbourhoods(cost, sequencing="partial", cam_id=cam, stream_index=si, k=k)
    np.testing.assert_array_equal(nb, _partial_reference(cost, cam, si, k))


def test_full_uses_time_nearest_images():
    t = np.array([0.0, 0.32, 0.1, 0.25, 0.2])
    nb = neighbourhoods(np.zeros((5, 5)), sequencing="full", cam_id=np.arange(5), timestamp_s=t, k=2)
    assert nb[0].tolist() == [2, 4]
    assert nb[4].tolist() == [3, 2]
    nb6 = neighbourhoods(np.zeros((5, 5)), sequencing="full", cam_id=np.arange(5), timestamp_s=t, k=6)
    assert (nb6[:, 4:] == -1).all()


def test_missing_sequencing_information_raises():
    with pytest.raises(SequencingError, match="stream_index"):
        neighbourhoods(np.zeros((2, 2)), sequencing="partial", cam_id=np.array([0, 1]))
    with pytest.raises(SequencingError, match="timestamp_s"):
        neighbourhoods(np.zeros((2, 2)), sequencing="full", cam_id=np.array([0, 1]))
    with pytest.raises(ValueError, match="sequencing"):
        neighbourhoods(np.zeros((2, 2)), sequencing="some", cam_id=np.array([0, 1]))


def test_none_is_permutation_equivariant(toy_sample):
    obs, _ = make_view(toy_sample, "none")
    pt = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id)
    nb = neighbourhoods(pt.cost, sequencing="none", cam_id=obs.cam_id, k=5)
    perm = np.random.default_rng(0).permutation(obs.n_images)
    inv = np.argsort(perm)
    nb_p = neighbourhoods(pt.cost[np.ix_(perm, perm)], sequencing="none", cam_id=obs.cam_id[perm], k=5)
    np.testing.assert_array_equal(np.where(nb_p >= 0, perm[np.maximum(nb_p, 0)], -1), nb[perm])
    assert inv.shape == perm.shape


def test_partial_neighbours_are_temporally_closer_than_none(scene_factory):
    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=40, seed=4)
    spread = {}
    for seq in ("none", "partial", "full"):
        obs, gt = make_view(sample, seq)
        pt = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id)
        nb = neighbourhoods(
            pt.cost, sequencing=seq, cam_id=obs.cam_id, stream_index=obs.stream_index,
            timestamp_s=obs.timestamp_s, order=pt.order, k=8,
        )  # fmt: skip
        spread[seq] = np.abs(gt.global_order[nb] - gt.global_order[:, None]).max()
    assert spread["full"] <= 8 and spread["partial"] <= spread["none"]


def test_chain_affinity_links_stream_neighbours():
    A = chain_affinity(np.array([0, 0, 0, 1, 1]), np.array([5, 1, 3, 0, 7]))
    expect = np.zeros((5, 5))
    for a, b in [(1, 2), (2, 0), (3, 4)]:
        expect[a, b] = expect[b, a] = 1
    np.testing.assert_array_equal(A, expect)
    W = chain_affinity(np.array([0, 0, 0, 1, 1]), np.array([5, 1, 3, 0, 7]), row_normalise=True)
    np.testing.assert_allclose(W.sum(1), 1.0)
    assert W[2, 0] == W[2, 1] == 0.5


def test_temporal_chain_matches_ground_truth_affinity(toy_sample):
    A = temporal_chain_affinity(toy_sample.timestamp_s, cam_id=toy_sample.cam_id)
    np.testing.assert_array_equal(A, toy_sample.affinity_binary())
    A_any = temporal_chain_affinity(toy_sample.timestamp_s)
    assert A_any.sum() == 2 * (toy_sample.n_images - 1)


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 4), st.integers(2, 12), st.integers(0, 10_000))
def test_temporal_interpolation_affinity_interpolates_time(n_cams, n, seed):
    """Rows sum to one, link only other cameras, and reproduce each interior image's timestamp."""
    rng = np.random.default_rng(seed)
    cam = rng.integers(0, n_cams, size=n)
    t = rng.permutation(n).astype(float) * 0.01 + rng.uniform(0, 1e-3)
    A = temporal_interpolation_affinity(t, cam)
    linked = A > 0
    assert not (linked & (cam[:, None] == cam[None, :])).any()
    has_other = np.array([(cam != c).any() for c in cam])
    np.testing.assert_allclose(A.sum(1), has_other.astype(float))
    other_t = [t[cam != cam[i]] for i in range(n)]
    interior = np.array([o.size > 0 and o.min() < t[i] < o.max() for i, o in enumerate(other_t)])
    np.testing.assert_allclose((A @ t)[interior], t[interior])
    # The links are the nearest other-camera images in time on each side.
    for i in np.flatnonzero(interior):
        before = t[(cam != cam[i]) & (t < t[i])].max()
        after = t[(cam != cam[i]) & (t > t[i])].min()
        assert set(t[linked[i]]) == {before, after}


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.integers(2, 4))
def test_pose_weighted_chain_keeps_the_links_and_fades_jumps(seed, n_cams):
    from gttnet.geometry.neighbours import pose_weighted_chain

    g = np.random.default_rng(seed)
    n = 24
    cam = np.sort(g.integers(0, n_cams, size=n))
    si = np.zeros(n, dtype=int)
    for c in range(n_cams):
        idx = np.nonzero(cam == c)[0]
        si[idx] = np.arange(idx.size)
    chain = chain_affinity(cam, si)
    poses = np.cumsum(g.normal(scale=0.01, size=(n, 5, 3)), axis=0)  # a slow walk through pose space
    links = np.argwhere(np.triu(chain) > 0)
    if len(links) < 3:
        return
    a, b = links[g.integers(len(links))]
    poses[b:] += 10.0  # one link (and others across the same cut) now jumps far
    w = pose_weighted_chain(chain, poses)
    assert (w[chain == 0] == 0).all()
    np.testing.assert_allclose(w, w.T)
    assert (w >= 0).all() and (w <= 1).all()
    assert w[a, b] < 1e-6 < np.median(w[chain > 0])
