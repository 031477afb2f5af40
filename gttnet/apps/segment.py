"""Event segmentation: split a capture's affinity graph into temporally disjoint events, each with its order."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg
from scipy.cluster.vq import kmeans2
from scipy.special import comb

from gttnet.geometry.ordering import (
    graph_components,
    normalised_laplacian,
    spectral_embedding,
    spectral_order,
    symmetrise,
)

__all__ = [
    "Segmentation",
    "adjusted_rand_index",
    "spectral_embedding",
    "spectral_clusters",
    "estimate_n_clusters",
    "segment_events",
    "segment_capture",
    "score_segmentation",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Segmentation:
    """Events found in an affinity graph.

    Args:
        labels: Event label of each image, shape ``(N,)`` int, ``0 .. n_events-1`` by decreasing size.
        order: Rank of each image in time inside its event (0 = first), shape ``(N,)`` int.
        n_events: Number of events.
        how: ``"components"`` (connected components) or ``"spectral"`` (spectral clustering).
    """

    labels: np.ndarray
    order: np.ndarray
    n_events: int
    how: str


def adjusted_rand_index(labels_true: np.ndarray, labels_pred: np.ndarray) -> float:
    """Adjusted Rand index of two labellings (Hubert & Arabie), from the contingency table.

    Args:
        labels_true: Reference label per item, shape ``(N,)``.
        labels_pred: Predicted label per item, shape ``(N,)``.

    Returns:
        ARI: 1 for identical partitions (up to renaming), about 0 for random ones.

    Example:
        >>> adjusted_rand_index(np.array([0, 0, 1, 1]), np.array([5, 5, 2, 2]))
        1.0
    """
    a = np.asarray(labels_true).ravel()
    b = np.asarray(labels_pred).ravel()
    if a.shape != b.shape:
        raise ValueError(f"labellings must have the same shape, got {a.shape} and {b.shape}")
    n = a.shape[0]
    _, ia = np.unique(a, return_inverse=True)
    _, ib = np.unique(b, return_inverse=True)
    table = np.zeros((ia.max() + 1 if n else 0, ib.max() + 1 if n else 0), dtype=np.int64)
    np.add.at(table, (ia, ib), 1)
    sum_ij = comb(table, 2).sum()
    sum_a = comb(table.sum(axis=1), 2).sum()
    sum_b = comb(table.sum(axis=0), 2).sum()
    expected = sum_a * sum_b / comb(n, 2) if n > 1 else 0.0
    top = 0.5 * (sum_a + sum_b)
    if top == expected:  # both partitions trivial (one cluster, or all singletons)
        return 1.0
    return float((sum_ij - expected) / (top - expected))


def estimate_n_clusters(A: np.ndarray, *, max_k: int = 8, min_ratio: float = 8.0) -> int:
    """Number of weakly linked groups from the largest relative gap of the normalised Laplacian spectrum.

    A chain of N images has small eigenvalues growing like ``k^2``; disjoint or weakly linked events add
    near-zero eigenvalues. The largest ratio ``lambda_{k+1} / lambda_k`` (k >= 2) marks the cut; ratios below
    ``min_ratio`` mean one group.

    Returns:
        Estimated number of clusters in ``[1, max_k]``.
    """
    S = symmetrise(A)
    m = min(max_k + 1, S.shape[0])
    vals = scipy.linalg.eigh(normalised_laplacian(S), eigvals_only=True, subset_by_index=[0, m - 1])
    vals = np.maximum(vals, 1e-12)
    ratios = vals[2:] / vals[1:-1]  # lambda_1 = 0 always; ratios[i] = lambda_{i+3} / lambda_{i+2} (1-based)
    if ratios.size == 0:
        return 1
    i = int(np.argmax(ratios))
    return i + 2 if ratios[i] >= min_ratio else 1


def spectral_clusters(A: np.ndarray, k: int, *, seed: int = 0, n_init: int = 10) -> np.ndarray:
    """Normalised spectral clustering (Ng-Jordan-Weiss) into ``k`` clusters, k-means by scipy.

    Returns:
        Cluster label per image, shape ``(N,)``, ``0 .. k-1`` by decreasing size.
    """
    if k <= 1:
        return np.zeros(np.asarray(A).shape[0], dtype=np.int64)
    U = spectral_embedding(A, k)
    U = U / np.maximum(np.linalg.norm(U, axis=1, keepdims=True), 1e-12)
    rng = np.random.default_rng(seed)
    best, best_cost = None, np.inf
    for _ in range(n_init):
        cent, lab = kmeans2(U, k, minit="++", seed=rng)
        cost = float(((U - cent[lab]) ** 2).sum())
        if cost < best_cost:
            best, best_cost = lab, cost
    if best is None:
        raise ValueError(f"spectral clustering needs n_init >= 1, got {n_init}")
    return _relabel_by_size(best)


def _relabel_by_size(labels: np.ndarray) -> np.ndarray:
    uniq, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    first = np.array([np.flatnonzero(inv == c)[0] for c in range(uniq.shape[0])])
    rank = np.lexsort((first, -counts))
    relabel = np.empty_like(rank)
    relabel[rank] = np.arange(rank.shape[0])
    return relabel[inv]


def _attach_small(labels: np.ndarray, features: np.ndarray | None, min_size: int) -> np.ndarray:
    """Merge components smaller than ``min_size`` into the large one nearest in feature space."""
    counts = np.bincount(labels)
    big = np.flatnonzero(counts >= min_size)
    if big.size == 0 or big.size == counts.size:
        return labels
    out = labels.copy()
    small = ~np.isin(labels, big)
    if features is None:
        out[small] = big[0]
        return _relabel_by_size(out)
    F = np.nan_to_num(np.asarray(features, dtype=np.float64).reshape(labels.shape[0], -1))
    ref = np.flatnonzero(~small)
    d = ((F[small][:, None, :] - F[ref][None, :, :]) ** 2).sum(-1)
    out[small] = labels[ref[np.argmin(d, axis=1)]]
    return _relabel_by_size(out)


def segment_events(
    affinity: np.ndarray,
    *,
    n_events: int | None = None,
    features: np.ndarray | None = None,
    min_size: int | None = None,
) -> Segmentation:
    """Events as connected components of the affinity graph (paper), else spectral clusters; order inside each.

    With ``n_events`` unknown, the components with at least ``min_size`` images are the events (smaller
    ones join the nearest event in ``features``); when that leaves one event, the spectral gap decides
    whether weakly linked events exist. With ``n_events`` given and a different component count,
    spectral clustering into ``n_events`` is used.

    Args:
        affinity: Non-negative affinity between images, shape ``(N, N)``.
        n_events: Known number of events, or None.
        features: Per-image features to attach small components, e.g. reconstructed shapes ``(N, J, 3)``.
        min_size: Smallest event in images (default ``max(3, N // 50)``).

    Returns:
        The :class:`Segmentation`.
    """
    S = symmetrise(affinity)
    n = S.shape[0]
    min_size = max(3, n // 50) if min_size is None else min_size
    labels = _attach_small(graph_components(S), features, min_size)
    how = "components"
    k = int(labels.max()) + 1
    if n_events is None and k == 1:
        n_events = estimate_n_clusters(S)
    if n_events is not None and n_events != k:
        labels, how, k = spectral_clusters(S, n_events), "spectral", n_events
    order = np.zeros(n, dtype=np.int64)
    for c in range(k):
        idx = np.flatnonzero(labels == c)
        if idx.size:
            order[idx] = spectral_order(S[np.ix_(idx, idx)])
    log.info("segmented %d images into %d events (%s)", n, k, how)
    return Segmentation(labels=labels, order=order, n_events=k, how=how)


def segment_capture(obs, *, method: str = "dloe", n_events: int | None = None, **options):
    """Reconstruct a capture with a method that returns an affinity, then segment its events.

    Args:
        obs: :class:`~gttdata.capture.views.Observations` (ground truth never enters).
        method: Registered method returning an affinity (``dloe``, ``pseudo``, ``gttnet``).
        n_events: Known number of events, or None.
        **options: Method options (``gttnet`` runs without its DLOE round unless ``refine=True``).

    Returns:
        ``(reconstruction, segmentation)``.
    """
    from gttnet.methods import reconstruct

    if method == "gttnet":
        # The learned affinity, which the segmentation was measured with, not the DLOE round's weights.
        options.setdefault("refine", False)
    rec = reconstruct(obs, method, **options)
    if rec.affinity is None:
        raise ValueError(f"method {method!r} returns no affinity; use dloe, pseudo or gttnet")
    return rec, segment_events(rec.affinity, n_events=n_events, features=rec.points3d)


def score_segmentation(seg: Segmentation, event_id: np.ndarray, global_order: np.ndarray) -> dict:
    """ARI against the true events and Kendall tau of the recovered order inside each found event.

    Args:
        seg: The segmentation.
        event_id: True event of each image, shape ``(N,)`` (view order).
        global_order: True time rank of each image, shape ``(N,)`` (view order).

    Returns:
        ``{"ari", "n_events", "n_true_events", "tau_per_event", "tau_mean"}`` (tau weighted by size).
    """
    from gttnet.evaluate.metrics import kendall_tau

    taus, sizes = [], []
    for c in range(seg.n_events):
        idx = np.flatnonzero(seg.labels == c)
        if idx.size >= 2:
            taus.append(kendall_tau(seg.order[idx], np.argsort(np.argsort(global_order[idx]))))
            sizes.append(idx.size)
    return {
        "ari": adjusted_rand_index(event_id, seg.labels),
        "n_events": seg.n_events,
        "n_true_events": int(np.unique(event_id).size),
        "tau_per_event": [round(t, 4) for t in taus],
        "tau_mean": float(np.average(taus, weights=sizes)) if taus else float("nan"),
    }
