"""Per-image neighbourhoods and chain affinities under the none / partial / full sequencing conditions."""

from __future__ import annotations

import logging

import numpy as np

from gttnet.errors import SequencingError

__all__ = [
    "neighbourhoods",
    "chain_affinity",
    "pose_weighted_chain",
    "temporal_chain_affinity",
    "temporal_interpolation_affinity",
]

log = logging.getLogger(__name__)

_SEQUENCING = ("none", "partial", "full")


def _stream_links(cam_id: np.ndarray, stream_index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Previous and next image of each image in its own stream (camera), shape ``(N,)`` each, -1 at ends."""
    n = cam_id.shape[0]
    order = np.lexsort((stream_index, cam_id))
    same = cam_id[order][1:] == cam_id[order][:-1]
    prev = np.full(n, -1, dtype=np.int64)
    nxt = np.full(n, -1, dtype=np.int64)
    prev[order[1:][same]] = order[:-1][same]
    nxt[order[:-1][same]] = order[1:][same]
    return prev, nxt


def _ranked(cost: np.ndarray, order: np.ndarray | None) -> np.ndarray:
    n = cost.shape[0]
    if order is None:
        order = np.argsort(cost, axis=1, kind="stable")
    order = np.asarray(order, dtype=np.int64)
    if order.shape != (n, n):
        raise ValueError(f"order must have shape {(n, n)}, got {order.shape}")
    return order


def _partial_rows(
    rank: np.ndarray, ok: np.ndarray, cam: np.ndarray, stream_index: np.ndarray, k: int
) -> np.ndarray:
    """Best-first growth for every row at once: from each other stream, one contiguous run from its best image.

    Row i's state per stream is the run ``[lo, hi]`` of stream positions taken so far; its frontier is the
    stream's image just before and just after the run (where that image is allowed), or, before the run
    starts, the stream's best-ranked allowed image (the seed). Each of the K steps takes, in every row, the
    best-ranked frontier image over all streams, as a priority queue over the frontiers would.

    Args:
        rank: Rank of image j in row i's ranking, shape ``(N, N)`` int64 (a permutation per row).
        ok: Allowed neighbours, shape ``(N, N)`` bool (finite cost, other camera).
        cam: Camera (= stream) of each image, shape ``(N,)``.
        stream_index: Index within its stream, shape ``(N,)``.
        k: Neighbours per image K.

    Returns:
        Neighbour indices, shape ``(N, K)`` int64, in the order taken, ``-1`` padded.
    """
    n = cam.shape[0]
    streams = np.unique(cam)
    members = [np.flatnonzero(cam == s) for s in streams]
    members = [m[np.argsort(stream_index[m], kind="stable")] for m in members]
    length = max(m.size for m in members)
    img = np.full((streams.size, length + 2), -1, dtype=np.int64)  # one -1 guard on each side
    for v, m in enumerate(members):
        img[v, 1 : m.size + 1] = m
    big = np.iinfo(np.int64).max
    safe = np.maximum(img, 0)  # guards read image 0, masked below
    # rank of each stream slot in each row, ``big`` at the guards and where not allowed: shape (N, V, L + 2)
    r = np.where((img >= 0)[None] & ok[:, safe], rank[:, safe], big)
    seed = r.argmin(axis=2)  # (N, V)
    rows = np.arange(n)[:, None]
    cols = np.arange(streams.size)[None, :]
    lo = np.zeros((n, streams.size), dtype=np.int64)  # 0 = not started (slot 0 is a guard)
    hi = np.zeros((n, streams.size), dtype=np.int64)
    out = np.full((n, k), -1, dtype=np.int64)
    for step in range(k):
        started = lo > 0
        left = r[rows, cols, np.maximum(lo - 1, 0)]
        right = r[rows, cols, np.minimum(hi + 1, length + 1)]
        cand = np.where(started, np.minimum(left, right), r[rows, cols, seed])
        v = cand.argmin(axis=1)
        best = cand[np.arange(n), v]
        live = best < big
        if not live.any():
            break
        i = np.flatnonzero(live)
        vi = v[i]
        go_left = started[i, vi] & (left[i, vi] < right[i, vi])
        slot = np.where(started[i, vi], np.where(go_left, lo[i, vi] - 1, hi[i, vi] + 1), seed[i, vi])
        out[i, step] = img[vi, slot]
        lo[i, vi] = np.where(started[i, vi] & ~go_left, lo[i, vi], slot)
        hi[i, vi] = np.where(started[i, vi] & go_left, hi[i, vi], slot)
    return out


def neighbourhoods(
    cost: np.ndarray,
    *,
    sequencing: str,
    cam_id: np.ndarray,
    stream_index: np.ndarray | None = None,
    timestamp_s: np.ndarray | None = None,
    k: int = 20,
    order: np.ndarray | None = None,
) -> np.ndarray:
    """The K neighbours of each image (the image itself excluded), restricted by the sequencing condition.

    * ``none``: the K best-ranked images of other cameras with finite pseudo-triangulation cost.
    * ``partial`` (paper Sec. 4.2, scenario 2): same-stream images are dropped, and from every other
      stream only images *adjacent among themselves* are kept. Rule used: best-first growth. Each
      other stream's best-ranked image seeds a run; repeatedly the best-ranked image among all runs'
      frontier images (the stream predecessor of a run's first image, the successor of its last, and
      the seeds not yet taken) is added, until K are taken. The kept images of each stream thus form
      one contiguous run of that stream, which rejects a similar-looking pose from another time of the
      same stream (repetitive motion), and come in near-cost order.
    * ``full``: the K images nearest in time (any camera, ties by index); ``cost`` is not used.

    Args:
        cost: Pair cost from :func:`~gttnet.geometry.triangulation.pseudo_triangulate`, shape ``(N, N)``;
            ``+inf`` entries are never neighbours under ``none`` and ``partial``.
        sequencing: ``"none"``, ``"partial"`` or ``"full"``.
        cam_id: Camera (= stream) of each image, shape ``(N,)``.
        stream_index: Index within its stream, shape ``(N,)`` (needed for ``partial``).
        timestamp_s: Capture times in seconds, shape ``(N,)`` (needed for ``full``).
        k: Number of neighbours K.
        order: Ranked neighbours, shape ``(N, N)`` (e.g. ``PseudoTriangulation.order``, which includes
            the near-parallel demotion); default: argsort of ``cost`` rows.

    Returns:
        Neighbour indices, shape ``(N, K)`` int64, best first, ``-1`` padded when fewer exist.

    Raises:
        SequencingError: If the condition needs ``stream_index`` or ``timestamp_s`` and it is None.

    Example:
        >>> cost = np.array([[np.inf, 1.0, 2.0], [1.0, np.inf, 3.0], [2.0, 3.0, np.inf]])
        >>> neighbourhoods(cost, sequencing="none", cam_id=np.array([0, 1, 1]), k=2).tolist()
        [[1, 2], [0, -1], [0, -1]]
    """
    if sequencing not in _SEQUENCING:
        raise ValueError(f"sequencing must be one of {_SEQUENCING}, got {sequencing!r}")
    cost = np.asarray(cost, dtype=np.float64)
    cam = np.asarray(cam_id)
    n = cam.shape[0]
    if cost.shape != (n, n):
        raise ValueError(f"cost must have shape {(n, n)} to match cam_id, got {cost.shape}")
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    out = np.full((n, k), -1, dtype=np.int64)
    if sequencing == "full":
        if timestamp_s is None:
            raise SequencingError("sequencing 'full' needs timestamp_s")
        t = np.asarray(timestamp_s, dtype=np.float64)
        dt = np.abs(t[:, None] - t[None, :])
        np.fill_diagonal(dt, np.inf)
        nb = np.argsort(dt, axis=1, kind="stable")[:, :k]
        m = min(k, n - 1)
        out[:, :m] = nb[:, :m]
        return out
    order = _ranked(cost, order)
    ok = np.isfinite(cost) & (cam[:, None] != cam[None, :])
    if sequencing == "none":
        ranked_ok = np.take_along_axis(ok, order, axis=1)
        # Stable partition: allowed images first, in rank order.
        keep = np.take_along_axis(order, np.argsort(~ranked_ok, axis=1, kind="stable"), axis=1)[:, :k]
        cnt = np.minimum(ok.sum(1), k)
        m = keep.shape[1]
        out[:, :m] = np.where(np.arange(m)[None, :] < cnt[:, None], keep, -1)
        return out
    if stream_index is None:
        raise SequencingError("sequencing 'partial' needs stream_index")
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(n)[None, :].repeat(n, 0), axis=1)
    return _partial_rows(rank, ok, cam, np.asarray(stream_index), k)


def pose_weighted_chain(chain: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """A within-stream chain whose links are weighted by how alike the two linked poses are.

    Each link (i, j) gets ``exp(-d_ij^2 / (2 m))``, with ``d_ij`` the Euclidean distance between the two
    images' whole poses and ``m`` the median of ``d^2`` over all links: a typical link keeps weight
    ``exp(-1/2)`` or more, a link that jumps between far-apart poses fades out. Meant for stream orders that
    are estimated rather than given (:func:`gttnet.model.inputs.order_streams`), where a wrong link would
    otherwise tie images from different moments together.

    Args:
        chain: Chain affinity, shape ``(N, N)``, non-zero at the links (e.g. :func:`chain_affinity`).
        poses: Poses of the N images, shape ``(N, J, 3)``, any unit; NaN joints count as 0.

    Returns:
        The weighted chain, shape ``(N, N)`` float64, symmetric where ``chain`` is, zero off the links.

    Example:
        >>> chain = chain_affinity(np.zeros(5, int), np.arange(5))
        >>> poses = np.array([0.0, 1.0, 2.0, 3.0, 10.0])[:, None, None] * np.ones((1, 1, 3))
        >>> np.round(pose_weighted_chain(chain, poses)[[0, 1, 2, 3], [1, 2, 3, 4]], 3).tolist()
        [0.607, 0.607, 0.607, 0.0]
    """
    c = np.asarray(chain, dtype=np.float64)
    n = c.shape[0]
    X = np.nan_to_num(np.asarray(poses, dtype=np.float64)).reshape(n, -1)
    rows, cols = np.nonzero(c)
    out = np.zeros_like(c)
    if rows.size == 0:
        return out
    d2 = ((X[rows] - X[cols]) ** 2).sum(axis=1)
    m = float(np.median(d2))
    w = np.exp(-d2 / (2.0 * m)) if m > 0 else np.ones_like(d2)
    out[rows, cols] = c[rows, cols] * w
    return out


def chain_affinity(
    cam_id: np.ndarray, stream_index: np.ndarray, *, row_normalise: bool = False
) -> np.ndarray:
    """Within-stream chain: links each image to its predecessor and successor in its own stream.

    Under partial sequencing this is the only timing known (docs/METHOD.md: the DLOE prior W_const, and the chain
    added to GTT-Net's sparse affinity). Streams are cameras; adjacency follows the ``stream_index`` rank, so
    gaps in the index (dropped frames) still link.

    Args:
        cam_id: Camera (= stream) of each image, shape ``(N,)``.
        stream_index: Index within the stream, shape ``(N,)``.
        row_normalise: False: symmetric 0/1 matrix. True: each row sums to 1 (0.5/0.5 inside a
            stream, 1 at its ends: the linear-interpolation chain); rows of one-image streams stay 0.

    Returns:
        Affinity of shape ``(N, N)`` float64, zero diagonal.

    Example:
        >>> chain_affinity(np.array([0, 0, 0, 1]), np.array([2, 0, 1, 0])).astype(int).tolist()
        [[0, 0, 1, 0], [0, 0, 1, 0], [1, 1, 0, 0], [0, 0, 0, 0]]
    """
    cam = np.asarray(cam_id)
    si = np.asarray(stream_index)
    if si.shape != cam.shape or cam.ndim != 1:
        raise ValueError(f"cam_id and stream_index must both have shape (N,), got {cam.shape} and {si.shape}")
    n = cam.shape[0]
    prev, nxt = _stream_links(cam, si)
    A = np.zeros((n, n))
    idx = np.arange(n)
    A[idx[prev >= 0], prev[prev >= 0]] = 1.0
    A[idx[nxt >= 0], nxt[nxt >= 0]] = 1.0
    if row_normalise:
        s = A.sum(1, keepdims=True)
        A = np.divide(A, s, out=np.zeros_like(A), where=s > 0)
    return A


def temporal_chain_affinity(timestamp_s: np.ndarray, *, cam_id: np.ndarray | None = None) -> np.ndarray:
    """Global time chain: links each image to the previous and next image in time (full sequencing).

    Args:
        timestamp_s: Capture times, seconds, shape ``(N,)``.
        cam_id: Optional camera of each image, shape ``(N,)``: if given, the previous and next images
            are taken among *other* cameras, as in the binary ground-truth affinity A^G.

    Returns:
        Symmetric 0/1 affinity, shape ``(N, N)`` float64, zero diagonal.

    Example:
        >>> temporal_chain_affinity(np.array([0.2, 0.0, 0.1])).astype(int).tolist()
        [[0, 0, 1], [0, 0, 1], [1, 1, 0]]
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"timestamp_s must have shape (N,), got {t.shape}")
    n = t.shape[0]
    order = np.argsort(t, kind="stable")
    A = np.zeros((n, n))
    if cam_id is None:
        A[order[:-1], order[1:]] = 1.0
    else:
        cam = np.asarray(cam_id)[order]
        for q in range(n):
            nxt = np.nonzero(cam[q + 1 :] != cam[q])[0]
            if nxt.size:
                A[order[q], order[q + 1 + nxt[0]]] = 1.0
    return np.maximum(A, A.T)


def temporal_interpolation_affinity(timestamp_s: np.ndarray, cam_id: np.ndarray) -> np.ndarray:
    """Each image as the linear interpolation of its time neighbours from other cameras (full sequencing).

    Row n links image n to ``p``, the latest image of another camera taken at or before ``t_n``, and
    ``q``, the earliest image of another camera taken after ``t_n``, with the weights that interpolate
    ``t_n`` between them: ``A[n, p] = (t_q - t_n) / (t_q - t_p)``, ``A[n, q] = (t_n - t_p) / (t_q - t_p)``.
    An image taken at the same time as another camera's (``t_p = t_n``) links to that one with weight
    1; at the ends of the capture the single neighbour gets weight 1. Under full sequencing this is the
    timing the solver is given, written as an affinity (the continuous ground-truth affinity when the
    timestamps are exact).

    Args:
        timestamp_s: Capture times, seconds, shape ``(N,)``.
        cam_id: Camera of each image, shape ``(N,)``.

    Returns:
        Row-stochastic affinity, shape ``(N, N)`` float64, zero diagonal (rows of a one-camera capture
        are zero).

    Example:
        >>> temporal_interpolation_affinity(np.array([0.0, 0.1, 0.4]), np.array([0, 1, 0])).tolist()
        [[0.0, 1.0, 0.0], [0.75, 0.0, 0.25], [0.0, 1.0, 0.0]]
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    cam = np.asarray(cam_id)
    if t.ndim != 1 or cam.shape != t.shape:
        raise ValueError(f"timestamp_s and cam_id must both have shape (N,), got {t.shape} and {cam.shape}")
    n = t.shape[0]
    prev_t = np.full(n, -np.inf)
    prev_i = np.full(n, -1, dtype=np.int64)
    next_t = np.full(n, np.inf)
    next_i = np.full(n, -1, dtype=np.int64)
    for c in np.unique(cam):
        members = np.flatnonzero(cam == c)
        members = members[np.argsort(t[members], kind="stable")]
        tc = t[members]
        other = cam != c
        lo = np.searchsorted(tc, t, side="right") - 1  # latest of camera c at or before t_n
        hi = np.searchsorted(tc, t, side="right")  # earliest of camera c after t_n
        has = other & (lo >= 0)
        cand = np.where(has, tc[np.clip(lo, 0, None)], -np.inf)
        better = has & (cand > prev_t)
        prev_t[better], prev_i[better] = cand[better], members[lo[better]]
        has = other & (hi < tc.shape[0])
        cand = np.where(has, tc[np.clip(hi, None, tc.shape[0] - 1)], np.inf)
        better = has & (cand < next_t)
        next_t[better], next_i[better] = cand[better], members[hi[better]]
    A = np.zeros((n, n))
    rows = np.arange(n)
    both = (prev_i >= 0) & (next_i >= 0) & (prev_t < t)
    w = np.zeros(n)
    w[both] = (t[both] - prev_t[both]) / (next_t[both] - prev_t[both])
    A[rows[both], prev_i[both]] = 1.0 - w[both]
    A[rows[both], next_i[both]] = w[both]
    only_prev = (prev_i >= 0) & ~both
    A[rows[only_prev], prev_i[only_prev]] = 1.0
    only_next = (next_i >= 0) & (prev_i < 0)
    A[rows[only_next], next_i[only_next]] = 1.0
    return A
