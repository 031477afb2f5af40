"""Batched solver of small convex quadratic programs on the probability simplex (DLOE's W-step rows)."""

from __future__ import annotations

import numpy as np

__all__ = ["project_simplex", "solve_simplex_qp"]


def project_simplex(v: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Euclidean projection of each row onto the probability simplex over its masked entries.

    Args:
        v: Points, shape ``(B, K)``.
        mask: Allowed entries, shape ``(B, K)`` bool; others are set to 0. All-False rows give zeros.

    Returns:
        Projections, shape ``(B, K)``, non-negative, each row summing to 1 over its allowed entries.

    Example:
        >>> project_simplex(np.array([[0.5, 0.5, 2.0]]), np.array([[True, True, False]])).tolist()
        [[0.5, 0.5, 0.0]]
    """
    k = v.shape[1]
    u = np.where(mask, v, -np.inf)
    s = -np.sort(-u, axis=1)
    finite = np.isfinite(s)
    css = np.cumsum(np.where(finite, s, 0.0), axis=1) - 1.0
    idx = np.arange(1, k + 1)
    cond = finite & (s - css / idx > 0)
    rho = np.maximum(cond.sum(axis=1), 1)
    theta = np.take_along_axis(css, rho[:, None] - 1, axis=1) / rho[:, None]
    out = np.maximum(np.where(mask, v, 0.0) - theta, 0.0)
    return np.where(mask, out, 0.0)


def solve_simplex_qp(
    H: np.ndarray,
    g: np.ndarray,
    mask: np.ndarray,
    *,
    x0: np.ndarray | None = None,
    n_iter: int = 300,
    tol: float = 1e-10,
) -> np.ndarray:
    """Minimise ``x^T H x + g^T x`` over the simplex, for a batch of small problems (FISTA with restart).

    Args:
        H: Symmetric positive semi-definite matrices, shape ``(B, K, K)``.
        g: Linear terms, shape ``(B, K)``.
        mask: Allowed entries, shape ``(B, K)`` bool.
        x0: Warm start, shape ``(B, K)`` (default: uniform over allowed entries).
        n_iter: Maximum iterations.
        tol: Stop when no entry moves more than this in one iteration.

    Returns:
        Minimisers, shape ``(B, K)``; zero rows where nothing is allowed.

    Example:
        >>> H = np.eye(2)[None]; g = np.array([[0.0, 1.0]])
        >>> np.round(solve_simplex_qp(H, g, np.ones((1, 2), bool)), 6).tolist()
        [[0.75, 0.25]]
    """
    H = np.where(mask[:, :, None] & mask[:, None, :], H, 0.0)
    # Step 1 / Lipschitz constant of the gradient 2 H x + g: 2 * largest eigenvalue per problem.
    lip = 2.0 * np.maximum(np.linalg.eigvalsh(H)[:, -1], 1e-30)
    step = (1.0 / lip)[:, None]
    x = project_simplex(np.ones_like(g) if x0 is None else x0, mask)
    y = x.copy()
    t = 1.0
    for _ in range(n_iter):
        grad = 2.0 * np.einsum("bkl,bl->bk", H, y) + g
        x_new = project_simplex(y - step * grad, mask)
        # Adaptive restart (O'Donoghue & Candes): drop momentum where it points uphill.
        uphill = ((y - x_new) * (x_new - x)).sum(axis=1) > 0
        t_new = 0.5 * (1.0 + np.sqrt(1.0 + 4.0 * t * t))
        beta = np.where(uphill, 0.0, (t - 1.0) / t_new)[:, None]
        y = x_new + beta * (x_new - x)
        moved = np.abs(x_new - x).max()
        x, t = x_new, t_new
        if moved < tol:
            break
    return x
