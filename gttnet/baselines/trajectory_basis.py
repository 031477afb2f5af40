"""The trajectory-basis baseline (Park et al.): each joint's trajectory is a few DCT basis functions of time."""

from __future__ import annotations

import logging

import numpy as np

from gttdata.capture.views import Observations
from gttnet.baselines._rays import image_folds, ray_projectors, ray_residuals, undetermined_joints
from gttnet.geometry.neighbours import temporal_chain_affinity
from gttnet.geometry.ordering import spectral_order
from gttnet.methods import Reconstruction, register_method

__all__ = ["dct_basis", "fit_trajectory_basis", "reconstruct_dct"]

log = logging.getLogger(__name__)

#: Candidate basis sizes for cross-validation (capped at N / 3 per sequence).
BASIS_SIZES: tuple[int, ...] = (4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128)


def dct_basis(timestamp_s: np.ndarray, k: int) -> np.ndarray:
    """Orthonormal DCT-II trajectory basis evaluated at (possibly irregular) times.

    Times are mapped affinely onto the DCT-II sample positions ``(i + 1/2) / N`` of the unit interval,
    so for evenly spaced times this is exactly the orthonormal DCT-II matrix.

    Args:
        timestamp_s: Image times, seconds, shape ``(N,)``.
        k: Number of basis functions (``1 <= k``).

    Returns:
        Basis matrix ``Theta``, shape ``(N, k)``; column 0 is constant.

    Example:
        >>> B = dct_basis(np.arange(8.0), 8)
        >>> bool(np.allclose(B.T @ B, np.eye(8)))
        True
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    n = t.shape[0]
    span = t.max() - t.min()
    tau = (t - t.min()) / span * (n - 1) if span > 0 else np.zeros(n)
    tau = (tau + 0.5) / n
    freq = np.arange(k)
    B = np.cos(np.pi * freq[None, :] * tau[:, None]) * np.sqrt(2.0 / n)
    B[:, 0] = np.sqrt(1.0 / n)
    return B


def _normal_equations(theta: np.ndarray, P: np.ndarray, centers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per joint ``M (J, 3k, 3k)`` and ``b (J, 3k)`` of ``sum_n ||P_nj (Theta_n beta_j - C_n)||^2``.

    Unknowns are ordered basis-major (``beta[k, a]`` at ``3 k + a``), so the system for the first ``k'``
    basis functions is the leading ``3 k'`` block. Each ``(a, b)`` block is ``Theta^T diag(P[:, j, a, b])
    Theta``, one batched matrix product (BLAS) per block.
    """
    k = theta.shape[1]
    J = P.shape[1]
    M = np.empty((J, k, 3, k, 3))
    for a in range(3):
        for b in range(a, 3):
            blk = np.matmul((theta[None, :, :] * P[:, :, a, b].T[:, :, None]).transpose(0, 2, 1), theta)
            M[:, :, a, :, b] = blk
            M[:, :, b, :, a] = blk
    PC = np.einsum("njab,nb->nja", P, centers)
    b = np.einsum("nk,nja->jka", theta, PC, optimize=True).reshape(J, 3 * k)
    return M.reshape(J, 3 * k, 3 * k), b


def _solve(M: np.ndarray, b: np.ndarray, k: int, ridge: float) -> np.ndarray:
    """Coefficients ``(J, k, 3)`` from the leading block of the normal equations, lightly ridged."""
    m = 3 * k
    A = M[:, :m, :m] + ridge * np.eye(m)
    return np.linalg.solve(A, b[:, :m, None])[..., 0].reshape(-1, k, 3)


def fit_trajectory_basis(
    timestamp_s: np.ndarray,
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    *,
    k: int,
    ridge: float = 1e-9,
    weight: np.ndarray | None = None,
) -> np.ndarray:
    """Least-squares DCT trajectories through the observed rays.

    Args:
        timestamp_s: Image times, seconds, shape ``(N,)``.
        centers: Camera centres, metres, shape ``(N, 3)``.
        rays: Unit viewing rays in world, shape ``(N, J, 3)``; ignored where not visible.
        visible: Observed-joint mask, shape ``(N, J)``.
        k: Number of DCT basis functions.
        ridge: Tikhonov weight on the coefficients (keeps poorly constrained high frequencies finite).
        weight: Per-observation weight of each ray residual, shape ``(N, J)``, or None (all 1).

    Returns:
        Joints in world, metres, shape ``(N, J, 3)``. A joint whose rays do not pin down even a straight-line
        trajectory (the first ``min(k, 2)`` basis functions; e.g. seen in one or two images, or never) is
        NaN: the ridge alone would place it anywhere.
    """
    theta = dct_basis(timestamp_s, k)
    M, b = _normal_equations(theta, ray_projectors(rays, visible, weight), centers)
    beta = _solve(M, b, k, ridge)
    X = np.einsum("nk,jka->nja", theta, beta)
    m0 = 3 * min(k, 2)
    ev = np.linalg.eigvalsh(M[:, :m0, :m0])
    X[:, ev[:, 0] <= 1e-9 * np.maximum(ev[:, -1], 1e-300)] = np.nan
    return X


def _cross_validate(
    timestamp_s: np.ndarray,
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    *,
    n_folds: int,
    ridge: float,
    patience: int = 2,
    weight: np.ndarray | None = None,
) -> tuple[int, dict[int, float]]:
    """Basis size minimising the mean held-out ray distance (K-fold over images).

    Sizes are tried in increasing order; the search stops once ``patience`` consecutive sizes failed to
    improve on the best (the held-out error is U-shaped in the basis size: bias, then overfitting).
    """
    n = timestamp_s.shape[0]
    sizes = [k for k in BASIS_SIZES if 3 * k <= n] or [min(BASIS_SIZES[0], max(n // 3, 1))]
    tpos = np.argsort(np.argsort(timestamp_s, kind="stable"), kind="stable")
    theta = dct_basis(timestamp_s, max(sizes))
    P = ray_projectors(rays, visible, weight)
    folds = []
    for held in image_folds(n, n_folds):
        test = np.isin(tpos, held)
        folds.append((test, *_normal_equations(theta[~test], P[~test], centers[~test])))
    count = max(int(visible.sum()), 1)
    cv: dict[int, float] = {}
    for k in sizes:
        err = 0.0
        for test, M, b in folds:
            X = np.einsum("nk,jka->nja", theta[test, :k], _solve(M, b, k, ridge))
            err += float(np.nansum(ray_residuals(X, centers[test], rays[test], visible[test])))
        cv[k] = err / count
        best = min(cv, key=cv.__getitem__)
        if sum(1 for q in cv if q > best) >= patience:
            break
    return min(cv, key=cv.__getitem__), cv


@register_method("dct", requires="full", needs="timestamps", summary="DCT trajectory basis (Park et al.)")
def reconstruct_dct(
    obs: Observations, *, k: int | None = None, n_folds: int = 5, ridge: float = 1e-9
) -> Reconstruction:
    """Trajectory-basis reconstruction: every joint follows ``X_p(t) = Theta(t) beta_p`` with a DCT basis.

    The basis is evaluated at the observed timestamps; ``beta`` minimises the squared distance of each
    observed joint from its viewing ray, ``sum ||(I - r r^T)(Theta_n beta_p - C_n)||^2``, one linear
    system per joint. The basis size is shared by all joints and chosen (unless ``k`` is given) by
    ``n_folds``-fold cross-validation over images: fit on the other folds, score the mean distance of
    the held-out observations from their rays, keep the size with the lowest score (sizes from
    :data:`BASIS_SIZES`, increasing, until two in a row do not improve) (Park et al. 2015
    choose the size by cross-validation to avoid low-reconstructability bases).

    Args:
        obs: Observations under full sequencing (timestamps known).
        k: Basis size; chosen by cross-validation when None.
        n_folds: Folds of the cross-validation.
        ridge: Tikhonov weight on the coefficients.

    Returns:
        Reconstruction with the temporal chain as affinity and the timestamp order as order.
    """
    t = np.asarray(obs.timestamp_s, dtype=np.float64)
    centers, rays, vis = obs.centers(), obs.rays(), obs.visible
    weight = None if obs.confidence is None else obs.weights()
    cv: dict[int, float] = {}
    if k is None:
        k, cv = _cross_validate(t, centers, rays, vis, n_folds=n_folds, ridge=ridge, weight=weight)
    if k < 1:
        raise ValueError(f"dct: k must be >= 1, got {k}")
    X = fit_trajectory_basis(t, centers, rays, vis, k=k, ridge=ridge, weight=weight)
    A = temporal_chain_affinity(t)
    log.debug("dct: k=%d (cv %s)", k, cv)
    info: dict = {"k": int(k), "cv_ray_error_m": {str(a): b for a, b in cv.items()}}
    lost = undetermined_joints("dct", X, vis, obs.skeleton.joint_names)
    if lost:
        info["undetermined_joints"] = lost
    return Reconstruction(points3d=X, affinity=A, order=spectral_order(A), info=info)
