"""The DLOE baseline (Xu & Dunn, ICCV 2019): alternate W-, D- and X-steps to estimate a Laplacian and 3D."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from gttdata.capture.views import Observations
from gttnet.baselines._simplex import solve_simplex_qp
from gttnet.geometry.neighbours import chain_affinity, neighbourhoods
from gttnet.geometry.triangulation import pseudo_triangulate
from gttnet.methods import Reconstruction, register_method

__all__ = ["DLOEParams", "candidate_neighbours", "d_step", "mds_embedding", "reconstruct_dloe", "w_step"]

log = logging.getLogger(__name__)

#: The reference's data are in inches; lambda3 and the stopping threshold are defined in those units, so
#: the W-, D-steps and the stopping rule see X in inches (the X-step is unit-free).
_INCH_PER_M = 1.0 / 0.0254


@dataclass(frozen=True)
class DLOEParams:
    """Parameters of the DLOE optimisation (defaults: the reference's ``param.yaml``).

    Args:
        lambda1: Weight of the compactness terms (embedding distance in the W-step, ``x^T L_sym x``).
        lambda2: Ray weight of the X-step; None pins observed joints to their rays (the reference's 1e10).
        lambda3: Weight of the ray-convergence penalty (inch^2 units, see module note).
        w_prior: Weight of the within-camera interpolation chain W_const in ``W`` (partial/full only).
        d_const: Weight of the identity in ``D = (1 - d_const) diag(d) + d_const I``.
        max_iter: Maximum number of W/D/X rounds.
        tol: Stop when ``||X_k+1 - X_k||_F / (N P)`` (X in inches) falls below this.
        n_candidates: Candidate neighbours per image in the W-step (best pseudo-triangulation partners).
        qp_iters: Iterations of the batched simplex QP solver per W-step.
        mask_missing: Fit each W row on the image's observed joints only (the reference drops the
            missing coordinates of x_n; filled-in joints are estimates, not data).
    """

    lambda1: float = 0.0015
    lambda2: float | None = None
    lambda3: float = 0.03
    w_prior: float = 0.1
    d_const: float = 0.5
    max_iter: int = 50
    tol: float = 1e-3
    n_candidates: int = 20
    qp_iters: int = 300
    mask_missing: bool = False


def candidate_neighbours(obs: Observations, cost: np.ndarray, order: np.ndarray, k: int) -> np.ndarray:
    """Candidate W-step neighbours of each image, all from other cameras, shape ``(N, k)``, -1 padded.

    * ``none`` and ``partial``: the GTT-Net neighbourhood rules
      (:func:`gttnet.geometry.neighbours.neighbourhoods`): the ``k`` best pseudo-triangulation
      partners, under ``partial`` kept as one contiguous run per other stream.
    * ``full``: the ``k`` images of other cameras nearest in time.

    The reference fits every row over all other-camera images; restricting to ``k`` candidates keeps
    each row's QP at ``k`` unknowns (O(N k^2) per W-step instead of O(N^3)). With k = 20 the true
    temporal neighbours are among the candidates whenever pseudo-triangulation ranks them top 20.
    """
    if obs.sequencing == "full":
        t = np.asarray(obs.timestamp_s, dtype=np.float64)
        dt = np.abs(t[:, None] - t[None, :])
        dt[obs.cam_id[:, None] == obs.cam_id[None, :]] = np.inf
        nb = np.argsort(dt, axis=1, kind="stable")[:, :k]
        return np.where(np.isfinite(np.take_along_axis(dt, nb, axis=1)), nb, -1)
    return neighbourhoods(
        cost, sequencing=obs.sequencing, cam_id=obs.cam_id, stream_index=obs.stream_index, k=k, order=order
    )


def mds_embedding(X: np.ndarray) -> np.ndarray:
    """1-D classical MDS embedding of the shapes: their scores on the first principal axis, shape ``(N,)``.

    Args:
        X: Shapes, shape ``(N, J, 3)`` (any length unit; the embedding has the same unit).
    """
    Y = X.reshape(X.shape[0], -1)
    Y = Y - Y.mean(axis=0)
    # The first principal axis from the small (3J, 3J) scatter matrix: much cheaper than an SVD of Y.
    _, vec = np.linalg.eigh(Y.T @ Y)
    return Y @ vec[:, -1]


def w_step(
    Xi: np.ndarray,
    cand: np.ndarray,
    conv: np.ndarray,
    emb: np.ndarray,
    W_const: np.ndarray,
    d: np.ndarray,
    params: DLOEParams,
    *,
    w0: np.ndarray | None = None,
    observed: np.ndarray | None = None,
) -> np.ndarray:
    """W-step: each row of W_var is a simplex-constrained least-squares fit over its candidates.

    Row n minimises, over ``w`` on the probability simplex (``c = 1 - w_prior`` with a chain prior,
    else 1; ``delta = D_nn``)::

        delta^2 ||x_n - (1 - c) W_const[n] X - c sum_m w_m x_m||^2
          + lambda1 c delta sum_m w_m (e_n - e_m)^2
          + lambda3 delta^2 (c sum_m w_m |conv_nm| + (1 - c) sum_m W_const[n, m] |conv_nm|)^2

    With ``sum w = 1`` the first residual is ``sum_m w_m (a_n - c x_m)``, so its Gram matrix holds
    only local differences (well conditioned). All rows are solved at once (batched FISTA).

    Args:
        Xi: Current shapes in inches, shape ``(N, J, 3)``.
        cand: Candidates, shape ``(N, K)``, -1 padded.
        conv: Ray convergence, shape ``(N, N)`` (NaN treated as 1: no triangulation support).
        emb: 1-D embedding in inches, shape ``(N,)``.
        W_const: Within-camera interpolation chain, shape ``(N, N)`` (zeros when unused).
        d: Current diagonal of D, shape ``(N,)``.
        params: Parameters.
        w0: Warm start, shape ``(N, K)``.
        observed: Optional mask ``(N, J)``: only row n's observed joints enter its data term.

    Returns:
        Candidate weights, shape ``(N, K)``; rows sum to 1 (0 for rows without candidates).
    """
    n = Xi.shape[0]
    use_prior = bool(W_const.any())
    c = 1.0 - params.w_prior if use_prior else 1.0
    Y = Xi.reshape(n, -1)
    aconv = np.abs(np.nan_to_num(conv, nan=1.0))
    a = Y - (1.0 - c) * (W_const @ Y) if use_prior else Y
    mask = cand >= 0
    cidx = np.where(mask, cand, 0)
    g = a[:, None, :] - c * Y[cidx]  # (N, K, 3P)
    if observed is not None:
        g = g * np.repeat(observed, 3, axis=1)[:, None, :]
    v = np.take_along_axis(aconv, cidx, axis=1) * mask
    s = (W_const * aconv).sum(axis=1) if use_prior else np.zeros(n)
    d2 = (d**2)[:, None, None]
    H = d2 * np.einsum("nka,nla->nkl", g, g) + params.lambda3 * d2 * c**2 * v[:, :, None] * v[:, None, :]
    lin = params.lambda1 * c * d[:, None] * (emb[:, None] - emb[cidx]) ** 2
    lin = lin + 2.0 * params.lambda3 * (d**2)[:, None] * c * (1.0 - c) * s[:, None] * v
    return solve_simplex_qp(H, lin, mask, x0=w0, n_iter=params.qp_iters)


def d_step(Xi: np.ndarray, W: np.ndarray, conv: np.ndarray, params: DLOEParams) -> np.ndarray:
    """D-step: ``d`` minimising ``sum_n (H_n d_n^2 + f_n d_n)`` with ``sum d = N`` and ``0 <= d <= N``.

    With ``D = c2 diag(d) + (1 - c2) I`` (``c2 = 1 - d_const``), the terms are the weighted residual
    ``||D (I - W) X||^2``, ``lambda1 sum_n D_nn sum_m W_nm ||x_n - x_m||^2`` and
    ``lambda3 sum_n (D_nn sum_m W_nm |conv_nm|)^2``. The QP is separable up to the sum constraint:
    ``d_n = clip((mu - f_n) / (2 H_n), 0, N)`` with ``mu`` found by bisection.

    Args:
        Xi: Shapes in inches, shape ``(N, J, 3)``.
        W: Row-stochastic weights, shape ``(N, N)``.
        conv: Ray convergence, shape ``(N, N)``.
        params: Parameters.

    Returns:
        ``d``, shape ``(N,)``, summing to N.
    """
    n = Xi.shape[0]
    c2 = 1.0 - params.d_const
    Y = Xi.reshape(n, -1)
    h = ((Y - W @ Y) ** 2).sum(axis=1)
    sq = (Y**2).sum(axis=1)
    dist2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * Y @ Y.T, 0.0)
    rho = (np.abs(np.nan_to_num(conv, nan=1.0)) * W).sum(axis=1)
    H = c2**2 * (h + params.lambda3 * rho**2) + 1e-12
    f = 2.0 * c2 * (1.0 - c2) * (h + params.lambda3 * rho**2) + params.lambda1 * c2 * (W * dist2).sum(axis=1)
    lo, hi = float(f.min()), float((f + 2.0 * H * n).max())
    for _ in range(100):
        mu = 0.5 * (lo + hi)
        if np.clip((mu - f) / (2.0 * H), 0.0, n).sum() < n:
            lo = mu
        else:
            hi = mu
    return np.clip((0.5 * (lo + hi) - f) / (2.0 * H), 0.0, n)


def _xstep(
    A: np.ndarray,
    centers: np.ndarray,
    rays: np.ndarray,
    vis: np.ndarray,
    params: DLOEParams,
    method: str,
    x_init: np.ndarray,
) -> np.ndarray:
    """The X-step with ``A``, shape ``(N, J, 3)``: numpy and SuperLU, or torch's batched dense solve for ``"dense"``.

    ``"auto"`` and ``"sparse"`` run :func:`gttnet.solvers.numpy_xstep.solve_structure_np`, which never imports
    torch (a second of start-up); ``"dense"`` keeps the torch Cholesky path of
    :func:`gttnet.solvers.xstep.solve_structure`. Both solve the same float64 systems (equal to rounding).
    X_init enters as a vanishing ridge: it keeps the solve unique where a joint is unseen in a linked component.
    """
    lam1, lam2 = params.lambda1, params.lambda2
    if method != "dense":
        from gttnet.solvers.numpy_xstep import solve_structure_np

        return solve_structure_np(A, centers, rays, vis, lambda1=lam1, lambda2=lam2, x_prior=x_init)
    import torch

    from gttnet.solvers.xstep import solve_structure

    X_t = solve_structure(torch.from_numpy(A), centers, rays, vis, lambda1=lam1, lambda2=lam2, method="dense",
                          x_prior=x_init)  # fmt: skip
    X: np.ndarray = X_t.numpy()
    return X


def _scatter(cand: np.ndarray, w: np.ndarray, n: int) -> np.ndarray:
    W = np.zeros((n, n))
    rows, cols = np.nonzero(cand >= 0)
    np.add.at(W, (rows, cand[rows, cols]), w[rows, cols])
    return W


@register_method("dloe", requires="none", summary="DLOE alternating W/D/X optimisation (Xu & Dunn 2019)")
def reconstruct_dloe(
    obs: Observations,
    *,
    xstep_method: str = "auto",
    candidates: str = "dense",
    x_start: np.ndarray | None = None,
    **overrides,
) -> Reconstruction:
    """DLOE: alternate the W-step, D-step and X-step from the pseudo-triangulation ``X_init``.

    Each round: embed the current X in 1-D (:func:`mds_embedding`), fit ``W_var`` row by row
    (:func:`w_step`), form ``W = 0.9 W_var + 0.1 W_const`` (within-camera interpolation chain, partial
    and full sequencing only; ``W = W_var`` without sequencing), fit ``d`` (:func:`d_step`) and
    ``D = 0.5 diag(d) + 0.5 I``, then solve the X-step with the affinity ``A = D W`` and pinned rays
    (:func:`gttnet.solvers.xstep.solve_structure`, lambda1 = 0.0015; ``lambda2`` overrides the pinning,
    e.g. with :func:`gttnet.solvers.xstep.noise_aware_lambda2`). Stops after ``max_iter`` rounds or
    when ``||dX||_F / (N P) < tol`` with X in inches (the reference's units).

    Args:
        obs: Observations (any sequencing).
        xstep_method: Solver of the X-step: ``"auto"`` and ``"sparse"`` the numpy/SuperLU solve (no torch),
            ``"dense"`` torch's batched Cholesky (see :func:`_xstep`).
        candidates: Pseudo-triangulation under ``none`` sequencing: ``"dense"`` (all pairs, the reference's
            search and the default), ``"kdtree"`` (:mod:`gttnet.geometry.candidates`: X_init, W-step
            candidates and convergences from the candidate pairs only) or ``"auto"`` (k-d tree above
            600 images).
        x_start: Structure the first W-step is fitted to, shape ``(N, J, 3)``, world metres; None starts
            from ``X_init``. Another method's estimate here makes DLOE a refinement of it (GTT-Net's
            ``refine``); the X-step's vanishing ridge still pulls toward ``X_init``, which ground truth never
            enters.
        **overrides: Fields of :class:`DLOEParams`.

    Returns:
        Reconstruction with the affinity ``A = D W`` (its order by the Fiedler vector).
    """
    if xstep_method not in ("auto", "dense", "sparse"):
        raise ValueError(f"dloe: xstep_method must be auto, dense or sparse, got {xstep_method!r}")
    unknown = sorted(set(overrides) - set(DLOEParams.__dataclass_fields__))
    if unknown:
        raise ValueError(
            f"method 'dloe' has no option {unknown[0]!r}; options: xstep_method, candidates, "
            + ", ".join(DLOEParams.__dataclass_fields__)
        )
    params = DLOEParams(**overrides)
    n = obs.n_images
    centers, rays, vis = obs.centers(), obs.rays(), obs.visible
    from gttnet.geometry.candidates import candidate_pseudo_triangulate, use_candidate_search

    if use_candidate_search(obs.sequencing, n, candidates):
        cp = candidate_pseudo_triangulate(centers, rays, vis, obs.cam_id)
        cand = cp.neighbours(params.n_candidates)
        conv = np.full((n, n), np.nan)  # NaN (no triangulation support) outside the candidate pairs
        used = cp.partners >= 0
        conv[np.nonzero(used)[0], cp.partners[used]] = cp.convergence[used]
        x_init = cp.X_init
    else:
        pt = pseudo_triangulate(centers, rays, vis, obs.cam_id)
        cand = candidate_neighbours(obs, pt.cost, pt.order, params.n_candidates)
        conv, x_init = pt.convergence, pt.X_init
    use_prior = obs.sequencing != "none" and params.w_prior > 0
    if use_prior:
        assert obs.stream_index is not None  # partial and full views carry their stream order
        W_const = chain_affinity(obs.cam_id, obs.stream_index, row_normalise=True)
    else:
        W_const = np.zeros((n, n))
    if x_start is None:
        X = x_init
    else:
        X = np.asarray(x_start, dtype=np.float64)
        if X.shape != x_init.shape:
            raise ValueError(f"x_start must have shape {x_init.shape} (N, J, 3), got {X.shape}")
    d = np.ones(n)
    w = None
    deltas: list[float] = []
    for _ in range(params.max_iter):
        Xi = X * _INCH_PER_M
        w = w_step(
            Xi,
            cand,
            conv,
            mds_embedding(Xi),
            W_const,
            d,
            params,
            w0=w,
            observed=vis if params.mask_missing else None,
        )
        W = _scatter(cand, w, n)
        if use_prior:
            W = (1.0 - params.w_prior) * W + params.w_prior * W_const
        d = d_step(Xi, W, conv, params)
        A = ((1.0 - params.d_const) * d + params.d_const)[:, None] * W
        X_new = _xstep(A, centers, rays, vis, params, xstep_method, x_init)
        deltas.append(float(np.linalg.norm((X_new - X) * _INCH_PER_M) / (n * obs.n_joints)))
        X = X_new
        if deltas[-1] < params.tol:
            break
    log.info("dloe: %d rounds, last dX %.3g", len(deltas), deltas[-1] if deltas else float("nan"))
    # Outputs are metres: the per-round change is reported in metres (the tolerance above works in inches).
    delta_m = [d / _INCH_PER_M for d in deltas]
    return Reconstruction(points3d=X, affinity=A, info={"iterations": len(deltas), "delta_m": delta_m})
