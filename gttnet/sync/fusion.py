"""Fusing pairwise clock measurements into one offset (and drift) per camera, robustly over the camera graph."""

from __future__ import annotations

import numpy as np

__all__ = ["fuse_clocks", "fuse_offsets", "huber_lstsq"]


def huber_lstsq(A: np.ndarray, y: np.ndarray, w0: np.ndarray, scale: float) -> np.ndarray:
    """``x`` minimising ``sum_r w0_r huber_scale(A_r x - y_r)`` by 20 rounds of IRLS, shape ``(A.shape[1],)``."""
    w = w0.copy()
    x = np.zeros(A.shape[1])
    for _ in range(20):
        sw = np.sqrt(w)
        x, *_ = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)
        res = np.abs(A @ x - y)
        w = w0 * np.where(res <= scale, 1.0, scale / np.maximum(res, 1e-12))
    return x


def fuse_offsets(n: int, pairs: list[tuple[int, int, float, float]], scale: float) -> np.ndarray:
    """Camera offsets from pairwise offset equations by Huber IRLS.

    Offsets ``o`` (``o[0] = 0``) from pair equations ``o_a - o_b = delta_ab`` by IRLS with a Huber
    weight of width ``scale`` seconds; each equation weighted by its consensus score.
    """
    A = np.zeros((len(pairs), n))
    y = np.zeros(len(pairs))
    w0 = np.zeros(len(pairs))
    for r, (i, j, delta, score) in enumerate(pairs):
        A[r, i], A[r, j], y[r], w0[r] = 1.0, -1.0, delta, max(score, 1e-9)
    return np.concatenate([[0.0], huber_lstsq(A[:, 1:], y, w0, scale)])


def fuse_clocks(
    n: int, eqs: list[tuple[int, int, float, float, float]], scale: float, drift: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Offsets and drifts (ppm) of ``n`` cameras from shifts measured at several times, by Huber IRLS.

    Each equation ``(i, j, tau_i, delta, score)`` says that camera ``i``'s local time ``tau_i`` and camera
    ``j``'s ``tau_i + delta`` are the same instant: ``o_i - o_j + e_i tau_i - e_j (tau_i + delta) = delta``
    with ``e = 1e-6 drift``; camera 0 is the gauge (``o_0 = 0``, ``drift_0 = 0``).
    """
    A = np.zeros((len(eqs), 2 * n))
    y = np.zeros(len(eqs))
    w0 = np.zeros(len(eqs))
    for r, (i, j, tau_i, delta, score) in enumerate(eqs):
        A[r, i], A[r, j] = 1.0, -1.0
        A[r, n + i], A[r, n + j] = 1e-6 * tau_i, -1e-6 * (tau_i + delta)
        y[r], w0[r] = delta, max(score, 1e-9)
    cols = [*range(1, n), *(range(n + 1, 2 * n) if drift else ())]
    x = np.zeros(2 * n)
    x[cols] = huber_lstsq(A[:, cols], y, w0, scale)
    return x[:n], x[n:]
