"""The high-pass-filter trajectory prior baseline (Valmadre & Lucey): penalise each joint's filtered trajectory."""

from __future__ import annotations

import logging

import numpy as np
import scipy.sparse as sp
from scipy.linalg import LinAlgError, solveh_banded

from gttdata.capture.views import Observations
from gttnet.baselines._rays import image_folds, ray_projectors, ray_residuals, undetermined_joints
from gttnet.geometry.neighbours import temporal_chain_affinity
from gttnet.methods import Reconstruction, register_method

__all__ = ["LAMBDAS", "difference_operator", "fit_highpass", "reconstruct_hpf"]

log = logging.getLogger(__name__)

#: Candidate prior weights for cross-validation (dimensionless: ray residuals and filter outputs are
#: both in metres).
LAMBDAS: tuple[float, ...] = tuple(10.0 ** np.arange(-1.0, 5.01, 0.5))


def difference_operator(n: int, order: int = 2, *, timestamp_s: np.ndarray | None = None) -> sp.csr_matrix:
    """Finite-difference high-pass filter along a sequence, shape ``(n - order, n)``.

    With ``timestamp_s`` (sorted), the differences are divided differences of the irregular samples,
    scaled by the mean spacing to the power ``order`` so that evenly spaced times give exactly the
    index-based filter (and the same prior weight means the same thing). Spacings are floored at 0.1 of
    the mean spacing (simultaneous images would make the system singular).

    Args:
        n: Sequence length.
        order: Difference order (1: velocity, 2: acceleration).
        timestamp_s: Sample times in increasing order, seconds, shape ``(n,)``, or None for even spacing.

    Example:
        >>> difference_operator(4).toarray().astype(int).tolist()
        [[1, -2, 1, 0], [0, 1, -2, 1]]
        >>> difference_operator(4, timestamp_s=np.array([0.0, 2.0, 4.0, 6.0])).toarray().tolist()
        [[1.0, -2.0, 1.0, 0.0], [0.0, 1.0, -2.0, 1.0]]
    """
    if timestamp_s is not None:
        t = np.asarray(timestamp_s, dtype=np.float64)
        if t.shape != (n,):
            raise ValueError(f"timestamp_s must have shape ({n},), got {t.shape}")
        if n <= order:
            return sp.csr_matrix((max(n - order, 0), n))
        h = np.diff(t)
        if np.any(h < 0):
            raise ValueError("timestamp_s must be sorted in increasing order")
        hbar = float(h.mean()) if h.size else 1.0
        h = np.maximum(h, 0.1 * hbar)  # (near-)simultaneous images: keep the system well conditioned
        # Divided differences: level q spans q + 1 samples; f[i..i+q] = (f[i+1..] - f[i..]) / (t[i+q] - t[i]).
        G = sp.eye(n, format="csr")
        for q in range(1, order + 1):
            m = G.shape[0]
            span = np.cumsum(np.concatenate([[0.0], h]))
            width = span[q : q + m - 1] - span[: m - 1]
            D = sp.diags(1.0 / width) @ (sp.eye(m - 1, m, k=1) - sp.eye(m - 1, m))
            G = D @ G
        fact = float(np.prod(np.arange(1, order + 1)))
        return sp.csr_matrix(G * (fact * hbar**order))
    G = sp.eye(n, format="csr")
    for _ in range(order):
        m = G.shape[0]
        G = (sp.eye(m - 1, m, k=1) - sp.eye(m - 1, m)) @ G
    return sp.csr_matrix(G)


def _prior_band(n: int, order: int, timestamp_s: np.ndarray | None) -> np.ndarray:
    """``G^T G (x) I3`` in the upper banded storage of ``scipy.linalg.solveh_banded``, shape ``(3 order + 1, 3N)``."""
    u = max(3 * order, 2)
    G = difference_operator(n, order, timestamp_s=timestamp_s)
    GtG = (G.T @ G).tocsr()
    prior_ab = np.zeros((u + 1, 3 * n))
    for d in range(order + 1):
        # Entry (3n + a, 3(n + d) + a) lives in row u - 3d, column 3(n + d) + a.
        prior_ab[u - 3 * d, 3 * d :] = np.repeat(GtG.diagonal(d)[: n - d], 3)
    return prior_ab


class _HighpassSystem:
    """Every joint's normal equations for one set of rays, solved for any prior weight.

    The normal matrix is ``blockdiag(P_n) + lam G^T G (x) I3`` per joint: only ``lam`` changes across a
    cross-validation grid, so the ray part, the filter part, the right-hand side and the check of which
    joints are pinned down are built once and each weight costs one scaled sum and the banded solves.
    Unknowns are ordered ``3 n + a`` (image-major), so the matrix has ``3 * order`` super-diagonals, in
    the upper banded storage of ``scipy.linalg.solveh_banded``.

    Args:
        centers: Camera centres in time order, metres, shape ``(N, 3)``.
        P: Ray projectors, shape ``(N, J, 3, 3)``.
        order: Difference order.
        timestamp_s: Sorted sample times for divided differences (None: even spacing).
        prior_ab: :func:`_prior_band` of these times, or None (built here).
    """

    def __init__(
        self,
        centers: np.ndarray,
        P: np.ndarray,
        order: int,
        timestamp_s: np.ndarray | None,
        prior_ab: np.ndarray | None = None,
    ) -> None:
        n, J = P.shape[:2]
        u = max(3 * order, 2)
        self.n, self.joints = n, J
        self.rays_ab = np.zeros((J, u + 1, 3 * n))  # blockdiag(P_n), shape (J, u + 1, 3N)
        for a in range(3):
            for b in range(a, 3):
                self.rays_ab[:, u - (b - a), np.arange(n) * 3 + b] = P[:, :, a, b].T
        # G^T G (x) I3, shared by every joint (and by every fold of a cross-validation: see _prior_band)
        self.prior_ab = _prior_band(n, order, timestamp_s) if prior_ab is None else prior_ab
        self.rhs = np.einsum("njab,nb->jna", P, centers).reshape(J, 3 * n)
        self.pinned = np.flatnonzero(_pinned_by_rays(P, order, timestamp_s))

    def solve(self, lam: float) -> np.ndarray:
        """Trajectories for prior weight ``lam``, shape ``(N, J, 3)``; NaN for joints not pinned down."""
        X = np.full((self.n, self.joints, 3), np.nan)
        lam_prior = lam * self.prior_ab
        for j in self.pinned:
            try:
                X[:, j] = solveh_banded(self.rays_ab[j] + lam_prior, self.rhs[j], check_finite=False).reshape(
                    self.n, 3
                )
            except LinAlgError:
                log.debug("hpf: joint %d is undetermined", j)
        return X


def fit_highpass(
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    *,
    lam: float,
    order: int = 2,
    timestamp_s: np.ndarray | None = None,
    weight: np.ndarray | None = None,
) -> np.ndarray:
    """Trajectories minimising ray residuals plus ``lam * ||G X_p||^2`` along an already ordered sequence.

    Args:
        centers: Camera centres in time order, metres, shape ``(N, 3)``.
        rays: Unit viewing rays in time order, shape ``(N, J, 3)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        lam: Weight of the high-pass penalty (dimensionless).
        order: Difference order of the filter ``G``.
        timestamp_s: The images' times, sorted, seconds, shape ``(N,)``: divided differences of the
            irregular samples (see :func:`difference_operator`); None: evenly spaced.
        weight: Per-observation weight of each ray residual (detector confidence), shape ``(N, J)``, or
            None (all 1).

    Returns:
        Joints in world, metres, shape ``(N, J, 3)``, in the same (time) order. A joint whose rays do not
        pin its trajectory down (too few of them for the prior's null space, e.g. seen in one or two
        images or never) is NaN: its system is singular and any value would be made up.
    """
    return _HighpassSystem(centers, ray_projectors(rays, visible, weight), order, timestamp_s).solve(lam)


def _pinned_by_rays(P: np.ndarray, order: int, timestamp_s: np.ndarray | None) -> np.ndarray:
    """Whether each joint's rays fix the trajectories the prior does not penalise, shape ``(J,)`` bool.

    The ``order``-th difference is blind to polynomials of degree < ``order`` in time (or in the image index
    when evenly spaced); a joint is determined only if its ray projectors, summed against that basis, leave
    none of those ``3 * order`` directions free. A Cholesky factorisation cannot be trusted to say so: with
    no ray at all the system is exactly singular, yet rounding can leave every pivot positive.
    """
    n = P.shape[0]
    s = np.arange(n, dtype=np.float64) if timestamp_s is None else np.asarray(timestamp_s, dtype=np.float64)
    span = float(s.max() - s.min()) if n > 1 else 0.0
    s = (s - s.min()) / span if span > 0 else np.zeros(n)
    B = s[:, None] ** np.arange(order)[None, :]  # (N, order)
    # N[j, (a, c), (b, d)] = sum_n B[n, a] B[n, b] P[n, j, c, d], as one matrix product (an einsum of three
    # operands loops in Python-level order and costs ten times more on a window of a long recording)
    BB = (B[:, :, None] * B[:, None, :]).reshape(n, order * order)
    M = (BB.T @ P.reshape(n, -1)).reshape(order, order, P.shape[1], 3, 3)
    N = M.transpose(2, 0, 3, 1, 4).reshape(P.shape[1], 3 * order, 3 * order)
    ev = np.linalg.eigvalsh(N)
    return np.asarray(ev[:, 0] > 1e-9 * np.maximum(ev[:, -1], 1e-300), dtype=bool)


def _cross_validate(
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    *,
    n_folds: int,
    order: int,
    timestamp_s: np.ndarray | None = None,
    search: str = "grid",
    weight: np.ndarray | None = None,
    start: float | None = None,
    prior_ab: np.ndarray | None = None,
) -> tuple[float, dict[float, float]]:
    """Prior weight minimising the mean held-out ray distance; held-out images keep only the prior.

    ``search="grid"`` scores every weight of :data:`LAMBDAS`; ``"bracket"`` scores every other one, then
    the two neighbours of the best (9 of 13 weights; the score is unimodal in ``log lam`` in practice).
    With ``start`` (e.g. the weight a neighbouring window chose), the grid weight nearest to it and its
    two neighbours are scored, then the grid is followed downhill until the score rises: the bracket's
    minimum wherever the score is unimodal, from 3 weights instead of 9 when the start is right.
    ``prior_ab`` (:func:`_prior_band` of ``timestamp_s``) saves rebuilding the filter for every fold.
    """
    if search not in ("grid", "bracket"):
        raise ValueError(f"hpf: search must be 'grid' or 'bracket', got {search!r}")
    n = visible.shape[0]
    folds = image_folds(n, n_folds)
    count = max(sum(int(visible[held].sum()) for held in folds), 1)
    if prior_ab is None:
        prior_ab = _prior_band(n, order, timestamp_s)
    P_all = ray_projectors(rays, visible, weight)

    def scores(lams: tuple[float, ...]) -> dict[float, float]:
        # Folds outer, weights inner: each fold's system is built once per call and only one is held at
        # a time; every weight's total still adds the folds in the same order.
        totals = dict.fromkeys(lams, 0.0)
        for held in folds:
            P = P_all.copy()
            P[held] = 0.0  # a held-out image's rays constrain nothing (as ray_projectors of the rest)
            system = _HighpassSystem(centers, P, order, timestamp_s, prior_ab)
            for lam in lams:
                X = system.solve(lam)
                totals[lam] += float(
                    np.nansum(ray_residuals(X[held], centers[held], rays[held], visible[held]))
                )
        return {lam: total / count for lam, total in totals.items()}

    if start is not None and start > 0:
        i = int(np.argmin(np.abs(np.log(LAMBDAS) - np.log(start))))
        cv = scores(tuple(LAMBDAS[k] for k in (i - 1, i, i + 1) if 0 <= k < len(LAMBDAS)))
        while True:  # downhill along the grid until both neighbours of the best are scored
            best = LAMBDAS.index(min(cv, key=cv.__getitem__))
            more = tuple(
                LAMBDAS[k] for k in (best - 1, best + 1) if 0 <= k < len(LAMBDAS) and LAMBDAS[k] not in cv
            )
            if not more:
                break
            cv.update(scores(more))
    elif search == "grid":
        cv = scores(LAMBDAS)
    else:
        cv = scores(LAMBDAS[::2])
        best = LAMBDAS.index(min(cv, key=cv.__getitem__))
        cv.update(scores(tuple(LAMBDAS[i] for i in (best - 1, best + 1) if 0 <= i < len(LAMBDAS))))
    return min(cv, key=cv.__getitem__), dict(sorted(cv.items()))


@register_method(
    "hpf",
    requires="full",
    needs="the global image order",
    summary="high-pass-filter trajectory prior (Valmadre & Lucey)",
)
def reconstruct_hpf(
    obs: Observations,
    *,
    lam: float | None = None,
    order: int = 2,
    n_folds: int = 5,
    spacing: str = "order",
    search: str = "grid",
    lam_start: float | None = None,
) -> Reconstruction:
    """High-pass-filter prior: ray residuals plus ``lam * ||G X_p||^2`` along the global image order.

    ``G`` is the ``order``-th finite difference along the time-ordered images (Valmadre & Lucey 2012
    use such high-pass filters as a general trajectory prior; the paper runs HPF with complete
    sequencing, so it is registered as needing ``full``). With ``spacing="order"`` uniform sampling is
    assumed: only the order of the images is used, not their timestamps (staggered cameras at equal rates
    sample evenly); ``spacing="time"`` uses divided differences of the timestamps (unequal rates, cameras
    started at arbitrary times, recovered clocks).
    Each joint is one sparse banded linear system in its ``3N`` coordinates; missing joints are filled
    by the prior alone. With detector confidences (``obs.confidence``) each ray residual is weighted
    by its joint's confidence.

    The weight ``lam`` (dimensionless) is chosen, unless given, by ``n_folds``-fold cross-validation
    over images on the grid :data:`LAMBDAS`: the held-out images' rays are dropped, the fit
    interpolates them through the prior, and the mean distance of their observations from their rays
    is scored; the lowest score wins.

    Args:
        obs: Observations under full sequencing.
        lam: Prior weight; chosen by cross-validation when None.
        order: Difference order of the filter (2 penalises acceleration).
        n_folds: Folds of the cross-validation.
        spacing: ``"order"`` (even spacing) or ``"time"`` (divided differences of the timestamps).
        search: Cross-validation over every weight (``"grid"``) or a coarse-to-fine ``"bracket"``.
        lam_start: Where the cross-validation starts (e.g. the weight the previous window of a long
            recording chose, :func:`gttnet.windowed.reconstruct_windowed`): the nearest grid weight and
            its neighbours, then downhill until the score rises, instead of ``search``.

    Returns:
        Reconstruction with the temporal chain as affinity and the time order as order.
    """
    if spacing not in ("order", "time"):
        raise ValueError(f"hpf: spacing must be 'order' or 'time', got {spacing!r}")
    seq = np.argsort(np.asarray(obs.timestamp_s), kind="stable")
    ts = np.asarray(obs.timestamp_s, dtype=np.float64)[seq] if spacing == "time" else None
    centers, rays, vis = obs.centers()[seq], obs.rays()[seq], obs.visible[seq]
    weight = None if obs.confidence is None else obs.weights()[seq]
    cv: dict[float, float] = {}
    prior_ab = _prior_band(obs.n_images, order, ts)
    if lam is None:
        lam, cv = _cross_validate(
            centers, rays, vis, n_folds=n_folds, order=order, timestamp_s=ts, search=search, weight=weight,
            start=lam_start, prior_ab=prior_ab,
        )  # fmt: skip
    if not lam > 0:
        raise ValueError(f"hpf: lam must be > 0, got {lam}")
    X = np.empty((obs.n_images, obs.n_joints, 3))
    P = ray_projectors(rays, vis, weight)
    X[seq] = _HighpassSystem(centers, P, order, ts, prior_ab).solve(lam)
    log.debug("hpf: lam=%g", lam)
    info: dict = {"lam": float(lam), "cv_ray_error_m": {f"{a:g}": b for a, b in cv.items()}}
    lost = undetermined_joints("hpf", X, obs.visible, obs.skeleton.joint_names)
    if lost:
        info["undetermined_joints"] = lost
    return Reconstruction(
        points3d=X, affinity=temporal_chain_affinity(np.asarray(obs.timestamp_s)), info=info
    )
