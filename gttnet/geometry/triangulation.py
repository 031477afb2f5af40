"""Pseudo-triangulation: pairwise ray-ray closest points giving the pair cost, neighbour order and X_init."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gttnet.errors import GttNetError

__all__ = ["PseudoTriangulation", "pseudo_triangulate", "closest_points_on_rays"]

log = logging.getLogger(__name__)

#: Rays whose squared sine of the angle between them is below this are treated as parallel.
_PARALLEL_EPS = 1e-12
#: The same in float32, whose ``1 - b^2`` cannot resolve smaller values (about 0.02 degrees).
_PARALLEL_EPS_32 = 1e-7


@dataclass(frozen=True)
class PseudoTriangulation:
    """Result of :func:`pseudo_triangulate` for N images of J joints.

    Args:
        cost: Pair cost D(i, j), the mean normalised closest-point error over joints valid for the pair,
            shape ``(N, N)``; ``+inf`` for same-camera pairs, the diagonal, and pairs with no valid joint.
        convergence: Mean ``r_i . r_j`` over the joints valid for the pair (1 = parallel rays),
            shape ``(N, N)``; NaN where no joint is valid.
        valid: Whether joint p is valid for the pair (visible in both, different cameras, non-parallel
            rays, both depths positive), shape ``(N, N, J)`` bool.
        order: Ranked neighbours of each image: stable argsort of its cost row, shape ``(N, N)`` int64;
            images with infinite cost come last (the near-parallel demotion applies to X_init only).
        X_init: Initial structure in world, metres, shape ``(N, J, 3)``; every visible joint lies on
            its observed ray (see :func:`pseudo_triangulate` for how the others are filled).
        source: Image whose ray triangulated each joint, shape ``(N, J)`` int64; ``-1`` where the
            joint was filled instead.
    """

    cost: np.ndarray
    convergence: np.ndarray
    valid: np.ndarray
    order: np.ndarray
    X_init: np.ndarray
    source: np.ndarray


def closest_points_on_rays(
    c1: np.ndarray, r1: np.ndarray, c2: np.ndarray, r2: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Depths of the closest points of two families of rays and the gap between them.

    The closest points are ``c1 + s r1`` and ``c2 + t r2`` (common perpendicular). The gap is
    computed from Plücker moments, ``|m1 . r2 + r1 . m2| / |r1 x r2|`` with ``m = c x r``, so two
    intersecting rays give a gap that is exactly zero up to rounding of the products.

    Args:
        c1: Ray origins in world, metres, shape ``(..., 3)``.
        r1: Unit ray directions, shape ``(..., 3)``.
        c2: Ray origins, shape ``(..., 3)`` (broadcast against ``c1``).
        r2: Unit ray directions, shape ``(..., 3)``.

    Returns:
        ``(s, t, gap)``: depths along each ray (metres) and the closest-point distance, each shape
        ``(...)``; NaN where the rays are parallel.

    Example:
        >>> s, t, gap = closest_points_on_rays(np.zeros(3), np.array([1.0, 0, 0]),
        ...                                    np.array([2.0, -1, 1]), np.array([0, 1.0, 0]))
        >>> float(s), float(t), float(gap)
        (2.0, 1.0, 1.0)
    """
    b = np.sum(r1 * r2, axis=-1)
    w0 = c1 - c2
    d = np.sum(r1 * w0, axis=-1)
    e = np.sum(r2 * w0, axis=-1)
    sin2 = 1.0 - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(sin2 > _PARALLEL_EPS, 1.0 / sin2, np.nan)
        s = (b * e - d) * inv
        t = (e - b * d) * inv
        triple = np.sum(np.cross(c1, r1) * r2, axis=-1) + np.sum(r1 * np.cross(c2, r2), axis=-1)
        gap = np.abs(triple) * np.sqrt(inv)
    return s, t, gap


def _pair_block(
    rows: slice, cols: slice, rT: np.ndarray, mT: np.ndarray, rC: np.ndarray, C: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validity, error and ``r_i . r_j`` of images ``rows`` against other-camera images ``cols``, ``(J, B, Nc)``.

    Missing rays are zero vectors, so their depths come out exactly 0 and fail the positive-depth test:
    no separate visibility mask is needed. Operations are in place to limit memory traffic.
    """
    ri, rj = rT[:, rows], rT[:, cols]
    rjt = rj.transpose(0, 2, 1)
    b = ri @ rjt  # r_i . r_j
    # d = r_i . (C_i - C_j), e = r_j . (C_i - C_j): the cross terms are (J,B,3)@(3,Nc) matmuls.
    d = ri @ C[cols].T
    np.subtract(rC[:, rows, None], d, out=d)
    e = (rj @ C[rows].T).transpose(0, 2, 1)
    e -= rC[:, None, cols]
    gap = mT[:, rows] @ rjt
    gap += ri @ mT[:, cols].transpose(0, 2, 1)  # Pluecker product m_i . r_j + r_i . m_j
    sin2 = np.multiply(b, b)
    np.subtract(1.0, sin2, out=sin2)
    eps = _PARALLEL_EPS if sin2.dtype == np.float64 else _PARALLEL_EPS_32
    ok = sin2 > eps
    np.maximum(sin2, eps, out=sin2)
    s = b * e
    s -= d  # s * sin2
    t = b * d
    np.subtract(e, t, out=t)  # t * sin2
    ok &= s > 0
    ok &= t > 0
    s += t  # (s + t) * sin2
    np.sqrt(sin2, out=sin2)
    # err = |gap_num| / sqrt(sin2) / (s + t) = |gap_num| sqrt(sin2) / ((s + t) sin2)
    np.abs(gap, out=gap)
    gap *= sin2
    s[~ok] = 1.0
    gap /= s
    return ok, gap, b


#: Ranked neighbours searched first for each image's first one that qualifies (see :func:`_first_in_rank`).
_RANK_HEAD = 16


def _first_in_rank(
    qualifies: Callable[[np.ndarray, np.ndarray], np.ndarray],
    needed: np.ndarray,
    head: int = _RANK_HEAD,
) -> tuple[np.ndarray, np.ndarray]:
    """For each image i and joint p, the first rank k whose neighbour qualifies, and whether one does.

    ``qualifies(rows, ks)`` gives, shape ``(len(rows), len(ks), J)``, whether the neighbour of rank ``ks``
    of each image in ``rows`` qualifies for each joint. The first ``head`` ranks of every image are
    searched first; only images with a ``needed`` joint left over search all N ranks. Where ``needed``,
    the same answer as searching all ranks at once, without forming the ``(N, N, J)`` array when the
    best-ranked neighbours suffice; elsewhere only the first ``head`` ranks are searched.

    Args:
        qualifies: See above.
        needed: Joints whose answer is used, shape ``(N, J)`` bool.
        head: Ranks searched for every image first.

    Returns:
        ``(first, found)``, each shape ``(N, J)``: the rank (0 where none qualifies) and whether one does.
    """
    n = needed.shape[0]
    rows = np.arange(n)
    block = qualifies(rows, np.arange(min(head, n)))
    first = np.argmax(block, axis=1)
    found = np.take_along_axis(block, first[:, None, :], axis=1)[:, 0]
    rest = np.flatnonzero((needed & ~found).any(axis=1)) if head < n else np.zeros(0, dtype=np.int64)
    if rest.size:
        block = qualifies(rest, np.arange(n))
        first[rest] = np.argmax(block, axis=1)
        found[rest] = np.take_along_axis(block, first[rest][:, None, :], axis=1)[:, 0]
    return first, found


def _fill_missing(X: np.ndarray, have: np.ndarray, order: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """Fill joints without a triangulation from the best-ranked neighbour that has one, else fallbacks."""

    def donor_has(rows: np.ndarray, ks: np.ndarray) -> np.ndarray:
        nb = order[rows[:, None], ks[None, :]]  # (R, k): the k-th ranked neighbours
        out: np.ndarray = have[nb] & finite[rows[:, None], nb][:, :, None]
        return out

    # only joints without their own estimate need a donor, and only joints some image has can get one
    first, found = _first_in_rank(donor_has, ~have & np.asarray(have.any(axis=0))[None, :])
    nb = np.take_along_axis(order, first, axis=1)
    return fill_from_donors(X, have, found, nb)


def fill_from_donors(X: np.ndarray, have: np.ndarray, found: np.ndarray, donor: np.ndarray) -> np.ndarray:
    """Joints without their own triangulation taken from a donor image, else from means of the triangulated ones.

    Where no donor has the joint: the joint's mean over all images that have it, else the image's centroid of
    its triangulated joints, else the mean of every triangulated joint (the origin when there is none).

    Args:
        X: Estimated joints in world, metres, shape ``(N, J, 3)`` (meaningful where ``have``).
        have: Joints with their own triangulation, shape ``(N, J)`` bool.
        found: Joints for which ``donor`` names an image that has the joint, shape ``(N, J)`` bool.
        donor: The donor image of each joint, shape ``(N, J)`` int (used where ``found``).

    Returns:
        The filled joints, shape ``(N, J, 3)``.
    """
    out = X.copy()
    fill = ~have & found
    out[fill] = X[donor[fill], np.nonzero(fill)[1]]
    rest = ~have & ~found
    if rest.any():
        cnt = have.sum(0)
        joint_mean = np.where(have[..., None], X, 0.0).sum(0) / np.maximum(cnt, 1)[:, None]
        img_cnt = have.sum(1)
        img_mean = np.where(have[..., None], X, 0.0).sum(1) / np.maximum(img_cnt, 1)[:, None]
        glob = X[have].mean(0) if have.any() else np.zeros(3)
        pick = np.where(
            (cnt > 0)[None, :, None],
            joint_mean[None],
            np.where((img_cnt > 0)[:, None, None], img_mean[:, None], glob),
        )
        out[rest] = pick[rest]
    return out


def project_lone(X: np.ndarray, C: np.ndarray, r: np.ndarray, lone: np.ndarray) -> np.ndarray:
    """Joints in ``lone`` (visible but triangulated with no partner) moved onto their own ray, at least 1 mm deep.

    Args:
        X: Estimated joints in world, metres, shape ``(N, J, 3)``.
        C: Camera centre of each image in world, metres, shape ``(N, 3)``.
        r: Unit viewing rays in world, shape ``(N, J, 3)``.
        lone: Joints to project, shape ``(N, J)`` bool.

    Returns:
        The joints, shape ``(N, J, 3)``: ``X`` where not ``lone``.
    """
    if not lone.any():
        return X
    depth = np.maximum(np.einsum("njk,njk->nj", X - C[:, None], r), 1e-3)
    return np.where(lone[..., None], C[:, None] + depth[..., None] * r, X)


def pseudo_triangulate(
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    cam_id: np.ndarray,
    *,
    min_angle_deg: float = 30.0,
    block_rows: int = 8,
) -> PseudoTriangulation:
    """Exhaustive pairwise pseudo-triangulation of N images (docs/METHOD.md, section 2).

    For every pair (i, j) of images from different cameras and every joint p visible in both, the
    closest points ``c_ij = C_i + s r_i`` and ``c_ji = C_j + t r_j`` of the two rays give the error
    ``|c_ij - c_ji| / (s + t)``. A joint is valid for the pair only if both depths are positive and the
    rays are not parallel; an invalid joint is skipped for that pair only. The pair cost is the mean
    error over valid joints (+inf if none); same-camera pairs are +inf.

    Neighbour order: each cost row is argsorted (``order``). For X_init, a neighbour whose mean ray
    convergence satisfies ``|cos| > cos(min_angle_deg)`` (near-parallel or near-opposite rays: a small
    triangulation angle and an unreliable depth) is *demoted*: it keeps its relative rank but comes after
    every non-demoted finite-cost neighbour. Measured on the synthetic ring captures (4 and 8 cameras,
    10 % missing): 30 degrees cuts the X_init error from 16.8 to 11.6 mm at 2 px noise and from 40 to
    30 mm at 5 px, and changes nothing noise-free; demoting in ``order`` too would widen the neighbours'
    temporal spread (median 7 -> 9 images), so ``order`` and ``cost`` are not demoted.

    X_init: a visible joint p of image i sits at ``C_i + s r_i`` where j is the best-ranked image (in
    the demoted ranking) for which p is valid, so it lies on its own ray. Joints that are missing in image i,
    or visible but valid for no pair, are filled with the estimate of p in the best-ranked neighbour
    that has one; a visible joint filled this way is then projected onto its own ray (depth clipped to
    be positive). If no ranked neighbour has p: the mean of p over all images, else the image's
    centroid.

    Args:
        centers: Camera centre of each image in world, metres, shape ``(N, 3)``.
        rays: Viewing rays in world, shape ``(N, J, 3)``, normalised here (anything where not visible).
        visible: Observed-joint mask, shape ``(N, J)`` bool.
        cam_id: Camera of each image, shape ``(N,)`` int.
        min_angle_deg: For X_init, demote neighbours whose mean ray angle is within this many degrees of
            parallel or opposite (0 = off).
        block_rows: Rows of the cost matrix computed at once (memory ~ 60 * block_rows * N * J bytes). The
            result does not depend on it; small blocks keep the temporaries in cache: 8 rows ran 1.5-1.7x
            faster than 64 at N = 300 and 1200 (``benchmarks/bench_pseudo.py --block-rows 8 16 32 64``).

    Returns:
        A :class:`PseudoTriangulation`.

    Raises:
        GttNetError: If no joint of any pair can be triangulated (e.g. a single camera).

    Example:
        >>> C = np.array([[0.0, -1, 0], [0.0, 1, 0]])
        >>> r = np.array([[[0.0, 1, 1]], [[0.0, -1, 1]]]) / np.sqrt(2)
        >>> pt = pseudo_triangulate(C, r, np.ones((2, 1), bool), np.array([0, 1]))
        >>> float(pt.cost[0, 1]), bool(np.allclose(pt.X_init[0, 0], [0, 0, 1]))
        (0.0, True)
    """
    C = np.asarray(centers, dtype=np.float64)
    r = np.asarray(rays, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    cam = np.asarray(cam_id)
    n, j = vis.shape
    if C.shape != (n, 3) or r.shape != (n, j, 3) or cam.shape != (n,):
        raise ValueError(
            f"expected centers (N, 3), rays (N, J, 3), visible (N, J), cam_id (N,) with N={n}, J={j}; got "
            f"{C.shape}, {r.shape}, {vis.shape}, {cam.shape}"
        )
    r = np.where(vis[..., None], r, 0.0)
    norm = np.linalg.norm(r, axis=-1)
    bad = vis & ~(np.isfinite(norm) & (norm > 0))
    if bad.any():
        n_bad, p_bad = np.argwhere(bad)[0]
        raise ValueError(
            f"visible joint {p_bad} of image {n_bad} has a zero or non-finite ray: {r[n_bad, p_bad]}"
        )
    r = r / np.where(vis, norm, 1.0)[..., None]  # unit rays; zero where missing
    # Work in camera-sorted order: the pairs of camera a with every later camera form one rectangle per
    # row block, so same-camera pairs and the mirrored half are never computed.
    perm = np.argsort(cam, kind="stable")
    Cp, cp = C[perm], cam[perm]
    r64 = np.ascontiguousarray(r[perm].transpose(1, 0, 2))  # (J, N, 3)
    # The pair costs only rank neighbours and test validity, so they run in float32 (about 1.6x faster
    # at N = 300); the Pluecker moments m = C x r and r.C are formed in float64 first, about the rig's
    # mean centre (the costs do not depend on the origin, and a rig far from it would cost float32 its
    # precision). X_init is triangulated in float64 from the chosen pairs.
    Cc = Cp - Cp.mean(axis=0)
    rT = r64.astype(np.float32)
    mT = np.cross(Cc[None], r64).astype(np.float32)
    rC = np.einsum("jnk,nk->jn", r64, Cc).astype(np.float32)
    Cp32 = Cc.astype(np.float32)
    cost = np.full((n, n), np.inf)
    conv = np.full((n, n), np.nan)
    valid = np.zeros((n, n, j), dtype=bool)
    ends = np.r_[np.nonzero(np.diff(cp))[0] + 1, n]
    for g0, g1 in zip(np.r_[0, ends[:-1]], ends, strict=True):
        for start in range(g0, g1 if g1 < n else g0, block_rows):
            rows, cols = slice(start, min(start + block_rows, g1)), slice(g1, n)
            ok, err, b = _pair_block(rows, cols, rT, mT, rC, Cp32)
            cnt = ok.sum(0, dtype=np.float32)  # float32 means: the costs stay float32 values (_rank_rows)
            err[~ok] = 0.0
            b[~ok] = 0.0
            with np.errstate(invalid="ignore", divide="ignore"):
                c_blk = np.where(cnt > 0, err.sum(0) / cnt, np.inf)
                v_blk = np.where(cnt > 0, b.sum(0) / cnt, np.nan)
            # written straight to the callers' image order (no permuted copy of the N x N x J array)
            fwd, back = np.ix_(perm[rows], perm[cols]), np.ix_(perm[cols], perm[rows])
            cost[fwd], conv[fwd], valid[fwd] = c_blk, v_blk, ok.transpose(1, 2, 0)
            cost[back], conv[back], valid[back] = c_blk.T, v_blk.T, ok.transpose(2, 1, 0)
    if not np.isfinite(cost).any():
        raise GttNetError(
            "pseudo-triangulation found no triangulable joint: need >= 2 cameras sharing a joint"
        )
    demoted = np.zeros((n, n), dtype=bool)
    if min_angle_deg > 0:
        demoted = np.abs(np.nan_to_num(conv, nan=0.0)) > np.cos(np.deg2rad(min_angle_deg))
    finite = np.isfinite(cost)
    order = _rank_rows(cost)
    init_order = _rank_rows(cost, tier=np.where(finite, demoted, 2)) if min_angle_deg > 0 else order
    X, source = _initial_structure(C, r, vis, valid, init_order, finite)
    return PseudoTriangulation(cost=cost, convergence=conv, valid=valid, order=order, X_init=X, source=source)


def _rank_rows(cost: np.ndarray, tier: np.ndarray | None = None) -> np.ndarray:
    """Stable argsort of each row by ``(tier, cost)``, shape ``(N, N)`` int64.

    The costs (non-negative or +inf, float32 values: the pair costs are computed in float32) are turned
    into unique int64 keys: the float32 bit pattern, which orders non-negative floats, with the tier
    above it and the column index below it. Unique keys make numpy's default (SIMD) sort give the stable
    order exactly, about 3x faster than a stable sort of the floats at N = 300.

    Args:
        cost: Pair costs, shape ``(N, N)``, each >= 0 or +inf and exactly representable in float32.
        tier: Optional primary key per entry, shape ``(N, N)``, integers 0..2.
    """
    n = cost.shape[1]
    # + 0.0 turns a -0.0, whose sign bit would sort it first, into +0.0
    key = (np.asarray(cost, dtype=np.float32) + np.float32(0.0)).view(np.int32).astype(np.int64)
    if tier is not None:
        key += np.asarray(tier, dtype=np.int64) << 31
    key *= n
    key += np.arange(n)
    return np.argsort(key, axis=-1).astype(np.int64, copy=False)


def _initial_structure(
    C: np.ndarray, r: np.ndarray, vis: np.ndarray, valid: np.ndarray, order: np.ndarray, finite: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """X_init and the source image of each joint (see :func:`pseudo_triangulate`)."""
    n, j = vis.shape

    def pair_valid(rows: np.ndarray, ks: np.ndarray) -> np.ndarray:
        out: np.ndarray = valid[rows[:, None], order[rows[:, None], ks[None, :]]]  # (R, k, J) in rank order
        return out

    # a pair is valid for visible joints only; a visible joint no other camera sees never is
    first, have = _first_in_rank(pair_valid, vis & (valid.any(axis=1)))
    src = np.where(have, np.take_along_axis(order, first, axis=1), -1)
    rows = np.broadcast_to(np.arange(n)[:, None], (n, j))
    m = np.maximum(src, 0)
    s, _, _ = closest_points_on_rays(C[rows], r, C[m], r[m, np.arange(j)[None, :]])
    X = C[:, None, :] + np.where(have, s, 0.0)[..., None] * np.where(have[..., None], r, 0.0)
    X = _fill_missing(X, have, order, finite)
    X = project_lone(X, C, r, vis & ~have)  # visible but valid for no pair: onto the own ray
    return X, src.astype(np.int64)
