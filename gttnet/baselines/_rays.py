"""Ray-constraint algebra shared by the trajectory solvers: projectors, residuals and held-out folds."""

from __future__ import annotations

import logging

import numpy as np

__all__ = ["ray_projectors", "ray_residuals", "image_folds", "undetermined_joints"]

log = logging.getLogger(__name__)


def ray_projectors(rays: np.ndarray, visible: np.ndarray, weight: np.ndarray | None = None) -> np.ndarray:
    """Orthogonal projectors ``I - r r^T`` onto the plane normal to each observed ray, optionally weighted.

    Since ``P`` is idempotent, ``w (X - C)^T P (X - C) = w ||P (X - C)||^2``: scaling a projector by an
    observation's weight (e.g. its detector confidence) weighs that ray's squared residual in every
    normal equation built from it.

    Args:
        rays: Unit viewing rays in world, shape ``(N, J, 3)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        weight: Per-observation weight, shape ``(N, J)``, or None (all 1).

    Returns:
        Projectors, shape ``(N, J, 3, 3)``; zero for missing joints (they constrain nothing).
    """
    P = np.eye(3) - rays[..., :, None] * rays[..., None, :]
    if weight is not None:
        P = P * np.asarray(weight, dtype=np.float64)[..., None, None]
    return np.where(visible[..., None, None], P, 0.0)


def ray_residuals(X: np.ndarray, centers: np.ndarray, rays: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """Distance of each point from its viewing ray, metres, shape ``(N, J)``; NaN where missing.

    Args:
        X: Points in world, metres, shape ``(N, J, 3)``.
        centers: Camera centre of each image, metres, shape ``(N, 3)``.
        rays: Unit viewing rays, shape ``(N, J, 3)``.
        visible: Observed-joint mask, shape ``(N, J)``.
    """
    v = X - centers[:, None, :]
    perp = v - (v * rays).sum(-1, keepdims=True) * rays
    return np.where(visible, np.linalg.norm(perp, axis=-1), np.nan)


def image_folds(n: int, n_folds: int, *, seed: int = 0) -> list[np.ndarray]:
    """Split images ``0..n-1`` into interleaved held-out folds (every ``n_folds``-th image of a random shift).

    Interleaving keeps each fold spread over the whole sequence, so a held-out image always has
    training images around it in time (a contiguous block would test extrapolation instead).

    Args:
        n: Number of images.
        n_folds: Number of folds (>= 2).
        seed: Seed of the random phase.

    Returns:
        ``n_folds`` arrays of held-out positions in ``0..n-1`` (positions in whatever order the caller
        indexes, e.g. time order).
    """
    shift = int(np.random.default_rng(seed).integers(n_folds))
    pos = (np.arange(n) + shift) % n_folds
    return [np.flatnonzero(pos == f) for f in range(n_folds)]


def undetermined_joints(method: str, X: np.ndarray, visible: np.ndarray, joint_names) -> list[str]:
    """Names of the observed joints a trajectory prior left NaN (too few rays), warned about once.

    Args:
        method: Method name for the warning.
        X: The reconstruction, shape ``(N, J, 3)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        joint_names: Name of each joint (J).

    Returns:
        The names, in joint order; empty when every observed joint was placed (joints no image observes
        are the registry's to report).
    """
    vis = np.asarray(visible, dtype=bool)
    lost = np.flatnonzero(np.isnan(X).any(axis=(0, 2)) & vis.any(axis=0))
    names = [joint_names[j] for j in lost]
    if names:
        log.warning(
            "%s: %s %s seen in too few images to fix a trajectory (%s observations): left NaN",
            method,
            "joints" if len(names) > 1 else "joint",
            ", ".join(names),
            ", ".join(str(int(vis[:, j].sum())) for j in lost),
        )
    return names
