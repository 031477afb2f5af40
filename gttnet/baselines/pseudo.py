"""The pseudo-triangulation baseline: X_init, each joint on its ray at the best other-camera ray's crossing."""

from __future__ import annotations

import numpy as np

from gttdata.capture.views import Observations
from gttnet.geometry.triangulation import pseudo_triangulate
from gttnet.methods import Reconstruction, register_method

__all__ = ["reconstruct_pseudo", "top_q_affinity"]


def top_q_affinity(cost: np.ndarray, *, q: int = 2) -> np.ndarray:
    """Symmetric binary affinity linking each image to its ``q`` cheapest finite-cost partners.

    Args:
        cost: Pair cost, shape ``(N, N)``, ``+inf`` for excluded pairs.
        q: Links kept per row.

    Returns:
        Affinity, shape ``(N, N)`` float64, 0/1, symmetric.

    Example:
        >>> c = np.array([[np.inf, 1.0, 2.0], [1.0, np.inf, 3.0], [2.0, 3.0, np.inf]])
        >>> top_q_affinity(c, q=1).astype(int).tolist()
        [[0, 1, 1], [1, 0, 0], [1, 0, 0]]
    """
    n = cost.shape[0]
    A = np.zeros((n, n))
    if n < 2:
        return A
    q = min(q, n - 1)
    best = np.argsort(cost, axis=1, kind="stable")[:, :q]
    rows = np.repeat(np.arange(n), q)
    cols = best.ravel()
    ok = np.isfinite(cost[rows, cols])
    A[rows[ok], cols[ok]] = 1.0
    return np.maximum(A, A.T)


@register_method("pseudo", requires="none", summary="pseudo-triangulation (X_init); no smoothness prior")
def reconstruct_pseudo(
    obs: Observations, *, q: int = 2, min_angle_deg: float = 0.0, candidates: str = "auto"
) -> Reconstruction:
    """Pseudo-triangulation: each visible joint at its closest point to the best other-camera ray.

    The affinity links each image to its ``q`` lowest-cost pseudo-triangulation partners (a geometry-only
    graph; sequencing information is not used), which gives a recovered order.

    Args:
        obs: Observations (any sequencing).
        q: Partners per image in the returned affinity.
        min_angle_deg: Demote partners whose rays are within this angle (see ``pseudo_triangulate``).
        candidates: Partner search under ``none`` sequencing: ``"dense"`` (all pairs), ``"kdtree"``
            (:func:`~gttnet.geometry.candidates.candidate_pseudo_triangulate`) or ``"auto"``.

    Returns:
        Reconstruction holding ``X_init``.
    """
    from gttnet.geometry.candidates import candidate_pseudo_triangulate, use_candidate_search

    if use_candidate_search(obs.sequencing, obs.n_images, candidates):
        cp = candidate_pseudo_triangulate(
            obs.centers(), obs.rays(), obs.visible, obs.cam_id, min_angle_deg=min_angle_deg
        )
        n = obs.n_images
        A = np.zeros((n, n))
        nb = cp.neighbours(q)
        rows, cols = np.nonzero(nb >= 0)
        A[rows, nb[rows, cols]] = 1.0
        return Reconstruction(points3d=cp.X_init, affinity=np.maximum(A, A.T))
    pt = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id, min_angle_deg=min_angle_deg)
    return Reconstruction(points3d=pt.X_init, affinity=top_q_affinity(pt.cost, q=q))
