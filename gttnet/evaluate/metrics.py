"""Pure reconstruction metrics: MPJPE, Procrustes-aligned MPJPE and sequence-order agreement."""

from __future__ import annotations

import numpy as np

__all__ = ["mpjpe_mm", "pa_mpjpe_mm", "kendall_tau"]


def _check_pair(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pred = np.asarray(pred, dtype=np.float64)
    gt = np.asarray(gt, dtype=np.float64)
    # The DLOE evaluation passed transposed (3P, N) matrices to its error function; demand (N, J, 3) exactly.
    if pred.ndim != 3 or pred.shape[-1] != 3:
        raise ValueError(f"pred must have shape (N, J, 3), got {pred.shape}")
    if gt.shape != pred.shape:
        raise ValueError(f"gt must have the shape of pred {pred.shape}, got {gt.shape}")
    if pred.shape[0] == 0 or pred.shape[1] == 0:
        raise ValueError(f"pred must have shape (N, J, 3) with N, J >= 1, got {pred.shape}")
    return pred, gt


def mpjpe_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """Mean per-joint position error over all images and joints (missing ones included), millimetres.

    Args:
        pred: Reconstructed joints in world, metres, shape ``(N, J, 3)``.
        gt: Ground-truth joints in world, metres, shape ``(N, J, 3)``.

    Returns:
        ``mean_{n,j} ||pred[n, j] - gt[n, j]||`` in millimetres (NaN if ``pred`` holds NaN).

    Raises:
        ValueError: If the shapes differ or are not ``(N, J, 3)``.

    Example:
        >>> gt = np.zeros((2, 1, 3))
        >>> pred = np.array([[[0.003, 0.004, 0.0]], [[0.0, 0.0, 0.001]]])
        >>> round(mpjpe_mm(pred, gt), 6)
        3.0
    """
    pred, gt = _check_pair(pred, gt)
    return float(np.linalg.norm(pred - gt, axis=-1).mean() * 1000.0)


def _procrustes_align(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Similarity transform (rotation, scale, translation) of each image's ``src`` onto ``dst``, ``(N, J, 3)``."""
    mu_s = src.mean(axis=1, keepdims=True)
    mu_d = dst.mean(axis=1, keepdims=True)
    a = src - mu_s
    b = dst - mu_d
    H = np.einsum("nja,njb->nab", a, b)
    U, S, Vt = np.linalg.svd(H)
    # Reflection guard (Umeyama): flip the smallest singular direction when det < 0.
    sign = np.sign(np.linalg.det(np.einsum("nab,nbc->nac", U, Vt)))
    sign = np.where(sign == 0, 1.0, sign)
    S = S.copy()
    S[:, -1] *= sign
    U = U.copy()
    U[:, :, -1] *= sign[:, None]
    R = np.einsum("nab,nbc->nac", U, Vt)  # maps row vectors: a @ R ~ b
    var = (a**2).sum(axis=(1, 2))
    scale = np.where(var > 0, S.sum(axis=1) / np.where(var > 0, var, 1.0), 1.0)
    out: np.ndarray = scale[:, None, None] * np.einsum("nja,nab->njb", a, R) + mu_d
    return out


def pa_mpjpe_mm(pred: np.ndarray, gt: np.ndarray) -> float:
    """MPJPE after aligning each image's shape to the ground truth by a similarity transform, millimetres.

    Args:
        pred: Reconstructed joints, metres, shape ``(N, J, 3)``.
        gt: Ground-truth joints, metres, shape ``(N, J, 3)``.

    Returns:
        Mean per-joint error after per-image Procrustes alignment (rotation, uniform scale, translation), mm.

    Example:
        >>> gt = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
        >>> pred = 2.0 * gt @ np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]) + 5.0
        >>> round(pa_mpjpe_mm(pred, gt), 6)
        0.0
    """
    pred, gt = _check_pair(pred, gt)
    return mpjpe_mm(_procrustes_align(pred, gt), gt)


def _inversions(p: np.ndarray) -> int:
    """Pairs ``i < j`` with ``p[i] > p[j]`` of a permutation of ``0..N-1``, shape ``(N,)``: O(N log^2 N).

    A bottom-up merge sort: at width w every element of a right half counts the larger elements of the
    left half of its block; with the block index as the high digit of a key, one sort merges all blocks.

    Example:
        >>> _inversions(np.array([2, 0, 1]))
        2
    """
    n = p.shape[0]
    x = p.astype(np.int64)
    idx = np.arange(n)
    count = 0
    width = 1
    while width < n:
        blk = idx // (2 * width)
        right = idx % (2 * width) >= width
        key = blk * n + x  # sorted within each half-block; block-major, so the left halves are sorted overall
        left_keys = key[~right]
        bigger = np.searchsorted(left_keys, (blk[right] + 1) * n) - np.searchsorted(
            left_keys, key[right], "right"
        )
        count += int(bigger.sum())
        x = np.sort(key) % n  # each block merged in place
        width *= 2
    return count


def kendall_tau(recovered_order: np.ndarray, true_order: np.ndarray) -> float:
    """Kendall rank correlation between a recovered and the true image order, up to reversal.

    A spectral order has a sign ambiguity and the direction of a sequence is unobservable from geometry
    alone, so the absolute value is returned: 1 for the true order or its reverse, about 0 for a random one.

    Args:
        recovered_order: Recovered rank of each image (0 = first), shape ``(N,)``.
        true_order: True rank of each image in time, shape ``(N,)``.

    Returns:
        ``|tau_b|`` in ``[0, 1]``; 1.0 when ``N < 2``.

    Example:
        >>> kendall_tau(np.array([3, 2, 1, 0]), np.array([0, 1, 2, 3]))
        1.0
    """
    a = np.asarray(recovered_order)
    b = np.asarray(true_order)
    if a.ndim != 1 or b.shape != a.shape:
        raise ValueError(
            f"recovered_order and true_order must both have shape (N,), got {a.shape} and {b.shape}"
        )
    if a.shape[0] < 2:
        return 1.0
    n = a.shape[0]
    ranks = np.arange(n)
    if np.array_equal(np.sort(a), ranks) and np.array_equal(np.sort(b), ranks):
        # Two rankings without ties (the usual case): tau_b = 1 - 4 discordant / (N (N - 1)), exactly.
        return float(abs(1.0 - 4.0 * _inversions(b[np.argsort(a)]) / (n * (n - 1.0))))
    from scipy.stats import kendalltau  # imported on use: scipy.stats takes 0.2-0.3 s to load

    tau = kendalltau(a, b).statistic
    return float(abs(tau)) if np.isfinite(tau) else 0.0
