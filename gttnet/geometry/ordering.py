"""Sequence recovery from an affinity graph: connected components, then a spectral order inside each."""

from __future__ import annotations

import logging

import numpy as np
from scipy.sparse import csr_matrix, issparse
from scipy.sparse.csgraph import connected_components

__all__ = [
    "NEGLIGIBLE_LINK",
    "graph_components",
    "normalised_laplacian",
    "pose_graph_affinity",
    "spectral_embedding",
    "spectral_order",
    "stream_consistent_order",
    "stream_ranks",
    "symmetrise",
    "timestamp_order",
]

log = logging.getLogger(__name__)


def _symmetric_affinity(A: np.ndarray | csr_matrix) -> np.ndarray | csr_matrix:
    """``(A + A^T) / 2`` with a zero diagonal, checked; a SciPy sparse ``A`` gives a CSR matrix."""
    if issparse(A):
        A = csr_matrix(A, dtype=np.float64)
        if A.shape[0] != A.shape[1]:
            raise ValueError(f"affinity must have shape (N, N), got {A.shape}")
        if not np.all(np.isfinite(A.data)):
            raise ValueError("affinity must be finite, found NaN or inf")
        if np.any(A.data < 0):
            raise ValueError(f"affinity must be non-negative, found minimum {A.data.min():.3g}")
        Ss = csr_matrix(0.5 * (A + A.T))
        Ss.setdiag(0.0)
        Ss.eliminate_zeros()
        return Ss
    A = np.asarray(A, dtype=np.float64)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"affinity must have shape (N, N), got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("affinity must be finite, found NaN or inf")
    if np.any(A < 0):
        raise ValueError(f"affinity must be non-negative, found minimum {A.min():.3g}")
    S: np.ndarray = 0.5 * (A + A.T)
    np.fill_diagonal(S, 0.0)
    return S


def graph_components(A: np.ndarray | csr_matrix, *, tol: float = 0.0) -> np.ndarray:
    """Connected components of the undirected graph of an affinity (an event segmentation).

    Args:
        A: Non-negative affinity, shape ``(N, N)`` (dense or SciPy sparse); symmetrised as
            ``(A + A^T) / 2``.
        tol: Edges with a weight ``<= tol`` are ignored.

    Returns:
        Component label of each image, shape ``(N,)`` int, labelled ``0, 1, ...`` by decreasing size
        (ties: by the lowest image index in the component).

    Example:
        >>> A = np.zeros((4, 4)); A[0, 1] = A[2, 3] = A[3, 2] = 1.0
        >>> graph_components(A).tolist()
        [0, 0, 1, 1]
    """
    return _components(_symmetric_affinity(A), tol)


def _components(S: np.ndarray | csr_matrix, tol: float) -> np.ndarray:
    """:func:`graph_components` of an already symmetrised affinity ``S``."""
    _, raw = connected_components(csr_matrix(S > tol), directed=False)  # sparse S: S > tol stays sparse
    labels = np.unique(raw)
    sizes = np.array([np.count_nonzero(raw == c) for c in labels])
    first = np.array([np.flatnonzero(raw == c)[0] for c in labels])
    rank = np.lexsort((first, -sizes))  # size descending, then first index
    relabel = np.empty_like(rank)
    relabel[rank] = np.arange(rank.shape[0])
    out: np.ndarray = relabel[np.searchsorted(labels, raw)]
    return out


#: Links of the symmetrised affinity at most this fraction of the largest degree are ignored when
#: :func:`spectral_order` splits components (a pose graph can hold weights of 1e-230 to far poses).
NEGLIGIBLE_LINK = 1e-12

#: Components larger than this, with at most this share of non-zero affinities, take the sparse solver.
_SPARSE_MIN_NODES = 400
_SPARSE_MAX_DENSITY = 0.05


def _fiedler(S: np.ndarray | csr_matrix) -> np.ndarray:
    """Fiedler vector of the combinatorial Laplacian ``diag(S 1) - S`` of a connected graph.

    Large sparse graphs (the top-Q affinities of GTT-Net and DLOE) use shift-invert Lanczos on the
    sparse Laplacian (``eigsh`` around a small negative shift, so ``L - sigma I`` is positive definite);
    the dense ``eigh`` costs ``O(n^3)``. A graph held together only by links far below rounding of the
    degrees (e.g. pose-graph weights of 1e-230) has several numerically zero eigenvalues, where Lanczos
    does not converge; it then falls back to the dense solver (its Fiedler vector is then one of them).
    """
    n = S.shape[0]
    nnz = int(S.nnz) if isinstance(S, csr_matrix) else int(np.count_nonzero(S))
    if n > _SPARSE_MIN_NODES and nnz <= _SPARSE_MAX_DENSITY * n * n:
        from scipy.sparse import diags
        from scipy.sparse.linalg import ArpackNoConvergence, eigsh

        W = csr_matrix(S)
        deg = np.asarray(W.sum(axis=1)).ravel()
        L = (diags(deg) - W).tocsc()
        # The shift sits below the small eigenvalues it must separate: a pose graph of weakly linked
        # clusters has eigenvalues of 1e-11 times the degree, which a shift of -1e-6 maps to nearly equal
        # values (~1,700 solves; GTT-Net's order of a 1,440-image capture took 0.14 s), a shift of -1e-9
        # with 20 Lanczos vectors does not (0.035 s; the same order).
        sigma = -1e-9 * max(float(deg.mean()), 1e-12)
        try:
            # Shift-invert converges in tens of iterations when it converges at all: bound the wait.
            v0 = np.ones(n) / np.sqrt(n) + np.arange(n) / n**1.5
            vals, vec = eigsh(L, k=2, sigma=sigma, which="LM", v0=v0, maxiter=500, ncv=min(n - 1, 20))
            return np.asarray(vec[:, np.argsort(vals)[-1]])
        except ArpackNoConvergence:
            log.warning(
                "spectral order: Lanczos did not converge on %d images (a near-split graph); dense", n
            )
    if isinstance(S, csr_matrix):
        S = S.toarray()
    L = np.diag(S.sum(axis=1)) - S
    # Only the two smallest eigenpairs are needed; subset_by_index avoids a full decomposition.
    import scipy.linalg  # imported on use (0.1 s of start-up)

    _, vec = scipy.linalg.eigh(L, subset_by_index=[0, min(1, n - 1)])
    return np.asarray(vec[:, -1])


def _runs_backwards(local: np.ndarray) -> bool:
    """Whether a local sequence anti-correlates with the image index (ties: last index placed first)."""
    rank = np.argsort(local)
    corr = float(np.dot(np.arange(rank.shape[0]) - rank.mean(), rank - rank.mean()))
    if abs(corr) > 1e-9:
        return corr < 0
    return bool(rank[0] > rank[-1])


def spectral_order(A: np.ndarray | csr_matrix, *, tol: float = 0.0) -> np.ndarray:
    """Recover the image sequence from an affinity by the Fiedler vector of its Laplacian.

    The graph ``(A + A^T) / 2`` is split into connected components (:func:`graph_components`): the
    components are placed one after another, largest first (ties by lowest image index), and each is
    ordered by sorting the Fiedler vector of its own combinatorial Laplacian ``L = diag(A 1) - A``.
    The Fiedler vector's sign is arbitrary; it is fixed so that the order correlates non-negatively with
    the image index, ties broken by putting the lowest index first (deterministic; under full sequencing
    the natural direction). Links lighter than :data:`NEGLIGIBLE_LINK` times the largest degree do not
    join components: the Laplacian cannot tell them from zero (its smallest eigenvalues become a
    numerically degenerate cluster, whose "Fiedler vector" is any mix of the parts).

    Args:
        A: Non-negative affinity, shape ``(N, N)``: a dense array or a SciPy sparse matrix (the same
            order, without ever forming ``N x N``; large sparse components are solved sparsely either way).
        tol: Edges with a weight ``<= tol`` are ignored when splitting components.

    Returns:
        Recovered rank of each image (0 = first), shape ``(N,)`` int64: a permutation of ``0..N-1``.

    Example:
        >>> A = np.zeros((4, 4))
        >>> for a, b in [(0, 2), (2, 1), (1, 3)]:
        ...     A[a, b] = A[b, a] = 1.0
        >>> spectral_order(A).tolist()
        [0, 2, 1, 3]
    """
    S = _symmetric_affinity(A)
    n = S.shape[0]
    deg_max = float(np.max(S.sum(axis=1))) if n else 0.0
    labels = _components(S, max(tol, NEGLIGIBLE_LINK * deg_max))
    sequence: list[np.ndarray] = []
    for c in range(int(labels.max()) + 1 if n else 0):
        idx = np.flatnonzero(labels == c)
        if idx.shape[0] <= 2:
            sequence.append(idx)
            continue
        f = _fiedler(S[idx][:, idx] if issparse(S) else S[np.ix_(idx, idx)])
        local = np.argsort(f, kind="stable")
        if _runs_backwards(local):
            local = local[::-1]
        sequence.append(idx[local])
    if len(sequence) > 1:
        log.debug("spectral_order: %d connected components", len(sequence))
    seq = np.concatenate(sequence) if sequence else np.zeros(0, dtype=np.int64)
    rank = np.empty(n, dtype=np.int64)
    rank[seq] = np.arange(n)
    return rank


def timestamp_order(timestamp_s: np.ndarray) -> np.ndarray:
    """Rank of each image by capture time (ties by image index): the order under full sequencing.

    Args:
        timestamp_s: Capture times, seconds, shape ``(N,)``.

    Returns:
        Rank of each image (0 = first), shape ``(N,)`` int64.

    Example:
        >>> timestamp_order(np.array([0.2, 0.0, 0.1, 0.0])).tolist()
        [3, 0, 2, 1]
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"timestamp_s must have shape (N,), got {t.shape}")
    rank = np.empty(t.shape[0], dtype=np.int64)
    rank[np.argsort(t, kind="stable")] = np.arange(t.shape[0])
    return rank


def stream_ranks(rank: np.ndarray, cam_id: np.ndarray) -> np.ndarray:
    """Each image's place among its own camera's images when all are put in the order ``rank`` gives.

    Turns a global order (recovered, or read from a file) into per-camera stream indices; ties keep the
    images' order in the input.

    Args:
        rank: A rank (or any sort key) of each image, shape ``(N,)``.
        cam_id: Camera (= stream) of each image, shape ``(N,)``.

    Returns:
        Index of each image within its stream, ``0..n_c - 1`` per camera, shape ``(N,)`` int64.

    Example:
        >>> stream_ranks(np.array([3, 0, 2, 1]), np.array([0, 0, 1, 1])).tolist()
        [1, 0, 1, 0]
    """
    r = np.asarray(rank)
    cam = np.asarray(cam_id)
    out = np.empty(cam.shape[0], dtype=np.int64)
    for c in np.unique(cam):
        mine = np.flatnonzero(cam == c)
        out[mine[np.argsort(r[mine], kind="stable")]] = np.arange(mine.size)
    return out


def stream_consistent_order(rank: np.ndarray, cam_id: np.ndarray, stream_index: np.ndarray) -> np.ndarray:
    """Make a recovered order agree with every stream's own order (partial sequencing).

    The direction of ``rank`` (a spectral order has none) is first chosen so that more consecutive
    images of each stream run forward than backward. Then each stream keeps the set of positions
    ``rank`` gave its images, reassigned to them in stream order: images of different streams
    interleave as recovered, and no stream's order is ever contradicted.

    Args:
        rank: Recovered rank of each image, a permutation of ``0..N-1``, shape ``(N,)``.
        cam_id: Camera (= stream) of each image, shape ``(N,)``.
        stream_index: Index within its stream, shape ``(N,)``.

    Returns:
        Rank of each image, shape ``(N,)`` int64, increasing along ``stream_index`` within every stream.

    Example:
        >>> stream_consistent_order(np.array([0, 3, 1, 2]), np.array([0, 0, 1, 1]), np.array([1, 0, 0, 1])).tolist()
        [3, 0, 1, 2]
    """
    r = np.asarray(rank, dtype=np.int64)
    cam = np.asarray(cam_id)
    si = np.asarray(stream_index)
    n = r.shape[0]
    if cam.shape != (n,) or si.shape != (n,):
        raise ValueError(
            f"rank, cam_id and stream_index must have shape (N,), got {r.shape}, {cam.shape}, {si.shape}"
        )
    if not np.array_equal(np.sort(r), np.arange(n)):
        raise ValueError("rank must be a permutation of 0..N-1")
    by_stream = np.lexsort((si, cam))
    same = cam[by_stream][1:] == cam[by_stream][:-1]
    steps = np.sign(np.diff(r[by_stream]))[same]
    if steps.sum() < 0:
        r = n - 1 - r
    out = np.empty(n, dtype=np.int64)
    for c in np.unique(cam):
        members = by_stream[cam[by_stream] == c]
        out[members] = np.sort(r[members])
    return out


def symmetrise(A: np.ndarray) -> np.ndarray:
    """``(|A| + |A|^T) / 2`` with a zero diagonal, shape ``(N, N)`` (no sign or finiteness check)."""
    A = np.asarray(A, dtype=np.float64)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise ValueError(f"affinity must have shape (N, N), got {A.shape}")
    S = np.asarray(0.5 * (np.abs(A) + np.abs(A).T), dtype=np.float64)
    np.fill_diagonal(S, 0.0)
    return S


def pose_graph_affinity(X: np.ndarray, *, k: int = 16, sparse: bool = False) -> np.ndarray | csr_matrix:
    """A k-nearest-neighbour graph over reconstructed poses, for ordering images by what they show.

    Each image is linked to the ``k`` images whose whole poses are nearest (Euclidean distance over all
    joint coordinates, any camera), with the Gaussian weight ``exp(-d^2 / s^2)``, ``s^2`` the median
    squared distance of those links. The spectral order of this graph (:func:`spectral_order`) follows
    the motion through pose space, as the W-step of DLOE does with its fitted weights.

    Args:
        X: Poses, shape ``(N, J, 3)``, any unit; NaN joints are not allowed.
        k: Links per image (clipped to ``N - 1``).
        sparse: Return a SciPy CSR matrix (``N k`` entries) instead of a dense array; the same entries, and
            :func:`spectral_order` gives the same order, without an ``N x N`` array.

    Returns:
        Non-negative affinity, shape ``(N, N)``, zero diagonal (not symmetric; :func:`spectral_order`
        symmetrises).

    Example:
        >>> t = np.linspace(0.0, 1.0, 30)
        >>> X = np.stack([np.cos(3 * t), np.sin(3 * t), t], axis=1)[:, None, :]
        >>> perm = np.random.default_rng(0).permutation(30)
        >>> rank = spectral_order(pose_graph_affinity(X[perm], k=4))
        >>> bool(np.all(np.diff(perm[np.argsort(rank)]) == 1) or np.all(np.diff(perm[np.argsort(rank)]) == -1))
        True
    """
    from scipy.spatial import cKDTree

    F = np.asarray(X, dtype=np.float64).reshape(len(X), -1)
    if not np.isfinite(F).all():
        raise ValueError("pose_graph_affinity: X holds NaN or inf joints; fill them first")
    n = F.shape[0]
    k = min(int(k), n - 1)
    A = csr_matrix((n, n))
    if k >= 1:
        dist, nbr = cKDTree(F).query(F, k=k + 1)
        dist, nbr = dist[:, 1:], nbr[:, 1:]  # drop each image itself
        s2 = float(np.median(dist**2))
        w = np.exp(-(dist**2) / s2) if s2 > 0 else np.ones_like(dist)
        rows = np.repeat(np.arange(n), k)
        off = nbr.ravel() != rows  # an image listed among its own neighbours (duplicate poses): no self-link
        # Each row's k neighbours are distinct, so no entry is summed twice.
        A = csr_matrix((w.ravel()[off], (rows[off], nbr.ravel()[off])), shape=(n, n))
    return A if sparse else A.toarray()


def normalised_laplacian(S: np.ndarray) -> np.ndarray:
    """``I - D^-1/2 S D^-1/2`` of a symmetric affinity ``S`` (isolated images get a zero row), ``(N, N)``."""
    d = S.sum(axis=1)
    inv = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 0.0)
    return np.asarray(np.eye(S.shape[0]) - inv[:, None] * S * inv[None, :], dtype=np.float64)


def spectral_embedding(A: np.ndarray, k: int) -> np.ndarray:
    """The ``k`` eigenvectors of the smallest eigenvalues of the normalised Laplacian of ``(A + A^T)/2``.

    Args:
        A: Non-negative affinity, shape ``(N, N)``.
        k: Embedding dimension.

    Returns:
        Coordinates, shape ``(N, k)`` (column 0 is the trivial one on a connected graph).
    """
    S = symmetrise(A)
    k = max(1, min(k, S.shape[0]))
    import scipy.linalg

    _, vec = scipy.linalg.eigh(normalised_laplacian(S), subset_by_index=[0, k - 1])
    return np.asarray(vec, dtype=np.float64)
