"""Spectral sequence recovery: chains, shuffles, disconnected graphs and input checks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gttnet.evaluate.metrics import kendall_tau
from gttnet.geometry.ordering import (
    graph_components,
    pose_graph_affinity,
    spectral_order,
    stream_consistent_order,
    timestamp_order,
)


def _chain(n: int, perm: np.ndarray) -> np.ndarray:
    """Affinity of a path visiting images perm[0], perm[1], ... (true rank of image perm[k] is k)."""
    A = np.zeros((n, n))
    A[perm[:-1], perm[1:]] = 1.0
    return A  # directed on purpose: spectral_order symmetrises


def test_shuffled_chain_recovered_exactly():
    rng = np.random.default_rng(0)
    n = 40
    perm = rng.permutation(n)
    rank = np.empty(n, dtype=int)
    rank[perm] = np.arange(n)
    order = spectral_order(_chain(n, perm))
    assert sorted(order.tolist()) == list(range(n))
    assert kendall_tau(order, rank) == pytest.approx(1.0)


def test_direction_follows_image_index():
    n = 10
    order = spectral_order(_chain(n, np.arange(n)[::-1]))
    np.testing.assert_array_equal(order, np.arange(n))


def test_noisy_chain_mostly_ordered():
    rng = np.random.default_rng(2)
    n = 60
    A = _chain(n, np.arange(n)) + np.diag(np.ones(n - 2), 2) * 0.5  # plus second neighbours
    a, b = rng.integers(0, n, size=(2, 4))
    A[a, b] += 0.01  # a few weak long-range shortcuts
    assert kendall_tau(spectral_order(A), np.arange(n)) > 0.95


def test_disconnected_components_largest_first():
    n = 9
    A = np.zeros((n, n))
    for a, b in [(5, 6), (6, 7), (7, 8), (0, 2), (2, 4), (1, 3)]:
        A[a, b] = 1.0
    labels = graph_components(A)
    assert labels.tolist() == [1, 2, 1, 2, 1, 0, 0, 0, 0]
    order = spectral_order(A)
    # component {5,6,7,8} first (largest), then {0,2,4}, then {1,3}
    np.testing.assert_array_equal(order[[5, 6, 7, 8]], [0, 1, 2, 3])
    np.testing.assert_array_equal(order[[0, 2, 4]], [4, 5, 6])
    np.testing.assert_array_equal(order[[1, 3]], [7, 8])


def test_isolated_images_and_empty():
    order = spectral_order(np.zeros((3, 3)))
    np.testing.assert_array_equal(order, [0, 1, 2])
    assert spectral_order(np.zeros((0, 0))).shape == (0,)


@pytest.mark.parametrize(
    ("A", "match"),
    [(np.zeros((3, 2)), "shape"), (-np.eye(3), "non-negative"), (np.full((2, 2), np.nan), "finite")],
)
def test_bad_affinity(A, match):
    with pytest.raises(ValueError, match=match):
        spectral_order(A)


def test_sparse_fiedler_matches_dense_on_a_large_chain(monkeypatch):
    """Above 400 nodes a sparse affinity takes shift-invert Lanczos; the order equals the dense one."""
    import gttnet.geometry.ordering as ordering

    g = np.random.default_rng(3)
    n = 600
    perm = g.permutation(n)
    A = np.zeros((n, n))
    A[perm[:-1], perm[1:]] = g.uniform(0.5, 1.0, n - 1)
    A[perm[:-2], perm[2:]] = g.uniform(0.0, 0.3, n - 2)
    sparse = ordering.spectral_order(A)
    monkeypatch.setattr(ordering, "_SPARSE_MIN_NODES", 10**9)
    dense = ordering.spectral_order(A)
    np.testing.assert_array_equal(sparse, dense)
    truth = np.empty(n, dtype=np.int64)
    truth[perm] = np.arange(n)
    assert sparse.tolist() == truth.tolist() or sparse.tolist() == (n - 1 - truth).tolist()


def test_graph_held_by_negligible_links_is_still_ordered():
    """Outlying poses linked by ~1e-50 weights: numerically split, Lanczos fails; the dense solver takes over."""
    g = np.random.default_rng(1)
    X = np.cumsum(g.normal(size=(600, 2, 3)), 0) * 0.05
    s = np.median(np.linalg.norm(np.diff(X.reshape(600, -1), axis=0), axis=1))
    far = X[g.integers(0, 600, 20)] + 15.0 * s * g.normal(size=(20, 2, 3)) / np.sqrt(6)
    A = pose_graph_affinity(np.concatenate([X, far]), k=16, sparse=True)
    assert graph_components(A).max() == 0  # one component, to the exact arithmetic
    order = spectral_order(A)
    assert sorted(order.tolist()) == list(range(620))
    truth = np.arange(600)
    assert abs(kendall_tau(order[:600], truth)) > 0.9  # the walk itself is still in order


def test_sparse_matrix_input_gives_the_dense_order():
    """A SciPy sparse affinity (GTT-Net's neighbourhood graph) is ordered exactly as its dense form."""
    from scipy.sparse import csr_matrix

    g = np.random.default_rng(4)
    for n in (9, 600):  # dense eigh below 400 nodes, shift-invert Lanczos above
        perm = g.permutation(n)
        A = np.zeros((n, n))
        A[perm[:-1], perm[1:]] = g.uniform(0.5, 1.0, n - 1)
        A[perm[:-3], perm[3:]] = g.uniform(0.0, 0.3, n - 3)
        A[np.arange(n), np.arange(n)] = 0.7  # a diagonal is ignored both ways
        half, rest = perm[: n // 2], perm[n // 2 :]
        A[rest[:, None], half[None, :]] = A[half[:, None], rest[None, :]] = 0.0  # two components
        np.testing.assert_array_equal(spectral_order(csr_matrix(A)), spectral_order(A))
        labels = graph_components(csr_matrix(A))
        np.testing.assert_array_equal(labels, graph_components(A))
        assert labels.max() == 1
    with pytest.raises(ValueError, match="non-negative"):
        spectral_order(csr_matrix(-np.eye(3)))


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 4), st.integers(1, 15), st.integers(0, 10_000))
def test_stream_consistent_order_never_contradicts_a_stream(n_cams, n, seed):
    rng = np.random.default_rng(seed)
    cam = rng.integers(0, n_cams, size=n)
    stream_index = rng.permutation(n)
    out = stream_consistent_order(rng.permutation(n), cam, stream_index)
    assert sorted(out.tolist()) == list(range(n))
    for c in np.unique(cam):
        members = np.flatnonzero(cam == c)
        along = out[members[np.argsort(stream_index[members])]]
        assert (np.diff(along) > 0).all()


def test_stream_consistent_order_keeps_a_consistent_order_and_fixes_direction():
    cam = np.array([0, 1, 0, 1, 0, 1])
    stream_index = np.array([0, 0, 1, 1, 2, 2])
    truth = np.arange(6)
    np.testing.assert_array_equal(stream_consistent_order(truth, cam, stream_index), truth)
    np.testing.assert_array_equal(stream_consistent_order(5 - truth, cam, stream_index), truth)
    # One stream's images swapped: only that stream changes, back into stream order.
    swapped = np.array([0, 1, 4, 3, 2, 5])
    np.testing.assert_array_equal(stream_consistent_order(swapped, cam, stream_index), truth)
    with pytest.raises(ValueError, match="permutation"):
        stream_consistent_order(np.array([0, 0, 1]), np.zeros(3, int), np.arange(3))


def test_timestamp_order_is_the_rank_in_time():
    t = np.array([0.3, 0.1, 0.2, 0.1])
    assert kendall_tau(timestamp_order(t), np.array([3, 0, 2, 1])) == 1.0
    np.testing.assert_array_equal(timestamp_order(t), [3, 0, 2, 1])


def test_pose_graph_order_recovers_a_shuffled_smooth_motion():
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 2.0, 120)
    # 5 joints moving smoothly and without revisiting a pose; noise well below the step between frames
    X = np.stack([np.cos(t + p) + p for p in range(5)], axis=0).T[..., None] * np.array([1.0, 0.5, 0.2])
    X = X + t[:, None, None] * np.array([0.3, 0.0, 0.1]) + rng.normal(scale=1e-4, size=X.shape)
    perm = rng.permutation(len(t))
    rank = spectral_order(pose_graph_affinity(X[perm], k=8))
    assert kendall_tau(rank, perm) > 0.99  # image i of the shuffled set is frame perm[i]


def test_sparse_pose_graph_is_the_dense_one():
    g = np.random.default_rng(5)
    X = np.cumsum(g.normal(size=(500, 4, 3)), axis=0)[g.permutation(500)]
    X[7] = X[8]  # duplicate poses: neither links to itself
    dense = pose_graph_affinity(X, k=6)
    sparse = pose_graph_affinity(X, k=6, sparse=True)
    np.testing.assert_array_equal(sparse.toarray(), dense)
    assert np.all(np.diag(dense) == 0)
    np.testing.assert_array_equal(spectral_order(sparse), spectral_order(dense))


def test_pose_graph_affinity_links_k_per_image_and_refuses_nan():
    X = np.random.default_rng(0).normal(size=(30, 4, 3))
    A = pose_graph_affinity(X, k=5)
    assert A.shape == (30, 30) and np.all(np.diag(A) == 0)
    assert np.all((A > 0).sum(axis=1) == 5) and np.all(A <= 1.0)
    X[3, 1, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        pose_graph_affinity(X, k=5)


@pytest.mark.parametrize("n", [2, 3, 16, 17, 301, 2048])
def test_kendall_tau_of_rankings_matches_scipy(n):
    # Rankings without ties take the O(N log^2 N) inversion count, not scipy.stats; ties still go to scipy.
    from scipy.stats import kendalltau

    rng = np.random.default_rng(n)
    a = rng.permutation(n)
    for b in (rng.permutation(n), np.argsort(np.argsort(a + rng.normal(0.0, n / 10, n))), a[::-1].copy()):
        assert kendall_tau(a, b) == pytest.approx(abs(kendalltau(a, b).statistic), abs=1e-12)
    tied = np.minimum(a, n // 2)
    assert kendall_tau(tied, a) == pytest.approx(abs(kendalltau(tied, a).statistic), abs=1e-12)
