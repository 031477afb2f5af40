"""Sub-quadratic pseudo-triangulation: epipolar pose descriptors, a k-d tree per camera pair, exact costs on candidates.

The dense :func:`~gttnet.geometry.triangulation.pseudo_triangulate` scores all ``N^2`` image pairs. Here
each image only meets a few candidate partners per other camera, found by nearest-neighbour search over
a per-image *epipolar descriptor*, then scored exactly as in the dense path.

The descriptor. Take two cameras a and b with centres ``C_a``, ``C_b`` and the baseline direction
``e = (C_b - C_a) / |C_b - C_a|``. Every plane through the baseline is an epipolar plane; a ray from
either centre lies in exactly one of them, with unit normal ``n = e x r / |e x r|``. If joint p of image i
(camera a) and joint p of image j (camera b) see the same 3-D point, both rays lie in the same epipolar
plane and their normals are *equal*, sign included (``e x (X - C_b) = e x (X - C_a)``). Writing each
normal in a basis ``(u, v)`` of the plane orthogonal to ``e`` gives two numbers per joint, so an image
has a ``2J`` descriptor per camera pair, and images of a and b taken at nearly the same instant have
nearly equal descriptors. A missing joint contributes zeros. Candidates are the ``per_camera`` nearest
images of each other camera under this descriptor (``scipy.spatial.cKDTree``): ``O(N log N)`` instead
of ``O(N^2)``.

The descriptor degrades for joints close to the baseline (opposite cameras on a ring look along it);
the exact pair cost of the candidates, not the descriptor distance, ranks the final neighbours, and
``benchmarks/bench_candidates.py`` measures recall against the dense search.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from gttnet.errors import GttNetError
from gttnet.geometry.triangulation import _PARALLEL_EPS, _PARALLEL_EPS_32, fill_from_donors, project_lone

__all__ = [
    "DENSE_MAX_IMAGES",
    "CandidatePseudoTriangulation",
    "use_candidate_search",
    "candidate_partners",
    "candidate_pseudo_triangulate",
    "epipolar_descriptors",
    "pair_costs",
]

log = logging.getLogger(__name__)

#: Under ``none`` sequencing, ``candidates="auto"`` searches all pairs up to this many images and uses the
#: k-d tree above it (measured at 1,440 images: same GTT-Net accuracy, ~10x less pseudo-triangulation time).
DENSE_MAX_IMAGES = 600

#: Image pairs scored at once by :func:`pair_costs` (memory ~ 300 * chunk * J bytes).
_PAIR_CHUNK = 4096


@dataclass(frozen=True)
class CandidatePseudoTriangulation:
    """Result of :func:`candidate_pseudo_triangulate` for N images, J joints and M candidate slots.

    Slots of each row are sorted by cost (finite first), so ``partners[:, :K]`` are the K best.

    Args:
        partners: Candidate partner of each slot, shape ``(N, M)`` int64, ``-1`` in unused slots.
        cost: Pair cost D(i, partner) as in the dense path, shape ``(N, M)``; ``+inf`` for unused slots
            and pairs with no valid joint.
        convergence: Mean ``r_i . r_j`` over the valid joints, shape ``(N, M)``; NaN where none.
        X_init: Initial structure in world, metres, shape ``(N, J, 3)`` (same rules as the dense path,
            restricted to the candidates).
        source: Image whose ray triangulated each joint, shape ``(N, J)`` int64; ``-1`` where filled.
    """

    partners: np.ndarray
    cost: np.ndarray
    convergence: np.ndarray
    X_init: np.ndarray
    source: np.ndarray

    def neighbours(self, k: int) -> np.ndarray:
        """The ``k`` best finite-cost partners of each image, shape ``(N, k)`` int64, ``-1`` padded."""
        n, m = self.partners.shape
        out = np.full((n, k), -1, dtype=np.int64)
        kk = min(k, m)
        take = self.partners[:, :kk]
        out[:, :kk] = np.where(np.isfinite(self.cost[:, :kk]), take, -1)
        return out


def use_candidate_search(sequencing: str, n_images: int, candidates: str) -> bool:
    """Whether a method's ``candidates`` option picks the k-d tree search for this capture.

    Args:
        sequencing: ``"none"``, ``"partial"`` or ``"full"`` (only ``none`` ranks by cost alone).
        n_images: Images N.
        candidates: ``"dense"``, ``"kdtree"`` or ``"auto"`` (k-d tree above :data:`DENSE_MAX_IMAGES`).

    Raises:
        ValueError: For another ``candidates`` value.
    """
    if candidates not in ("auto", "dense", "kdtree"):
        raise ValueError(f"candidates must be 'auto', 'dense' or 'kdtree', got {candidates!r}")
    return sequencing == "none" and (
        candidates == "kdtree" or (candidates == "auto" and n_images > DENSE_MAX_IMAGES)
    )


def _unit_rays(rays: np.ndarray, visible: np.ndarray) -> np.ndarray:
    r = np.where(visible[..., None], rays, 0.0)
    norm = np.linalg.norm(r, axis=-1, keepdims=True)
    out: np.ndarray = np.divide(r, norm, out=np.zeros_like(r), where=norm > 0)
    return out


def epipolar_descriptors(
    rays: np.ndarray, visible: np.ndarray, center_a: np.ndarray, center_b: np.ndarray
) -> np.ndarray:
    """Epipolar-plane descriptors of images under the camera pair (a, b) (see the module docstring).

    Args:
        rays: Unit viewing rays in world of images of camera a or b, shape ``(N, J, 3)``.
        visible: Observed joints, shape ``(N, J)`` bool.
        center_a: Centre of camera a in world, metres, shape ``(3,)``.
        center_b: Centre of camera b, shape ``(3,)``.

    Returns:
        Descriptors, shape ``(N, 2 J)`` float64: per joint the unit epipolar-plane normal in the basis
        ``(u, v)`` orthogonal to the baseline; zeros for missing joints (and joints on the baseline).
    """
    e = np.asarray(center_b, dtype=np.float64) - np.asarray(center_a, dtype=np.float64)
    norm_e = np.linalg.norm(e)
    if not norm_e > 0:
        raise ValueError(f"cameras at the same centre {center_a} have no baseline")
    e = e / norm_e
    helper = np.eye(3)[np.argmin(np.abs(e))]
    u = np.cross(e, helper)
    u /= np.linalg.norm(u)
    v = np.cross(e, u)
    n = np.cross(e, rays)  # (N, J, 3), |n| = sin(angle to the baseline)
    d = np.stack([n @ u, n @ v], axis=-1)
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.divide(d, norm, out=np.zeros_like(d), where=(norm > 1e-9) & visible[..., None])
    out: np.ndarray = d.reshape(d.shape[0], -1)
    return out


def candidate_partners(
    centers: np.ndarray, rays: np.ndarray, visible: np.ndarray, cam_id: np.ndarray, *, per_camera: int = 12
) -> np.ndarray:
    """Candidate partners of every image: its ``per_camera`` nearest images of each other camera.

    Nearest under the epipolar descriptor of the camera pair, found with one ``cKDTree`` per ordered
    camera pair; cost ``O(V^2 N log N)`` for V cameras instead of ``O(N^2)``.

    Args:
        centers: Camera centre of each image in world, metres, shape ``(N, 3)``.
        rays: Viewing rays in world, shape ``(N, J, 3)`` (normalised here; anything where not visible).
        visible: Observed joints, shape ``(N, J)`` bool.
        cam_id: Camera of each image, shape ``(N,)``.
        per_camera: Candidates taken from each other camera.

    Returns:
        Partner indices, shape ``(N, (V - 1) * per_camera)`` int64, ``-1`` where a camera has fewer images.
    """
    from scipy.spatial import cKDTree

    C = np.asarray(centers, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    r = _unit_rays(np.asarray(rays, dtype=np.float64), vis)
    cam = np.asarray(cam_id)
    members = _camera_members(cam)
    centre_of = {c: C[ic].mean(0) for c, ic in members.items()}

    def nearest(a: Any, b: Any, kq: int) -> np.ndarray:
        ia, ib = members[a], members[b]
        da = epipolar_descriptors(r[ia], vis[ia], centre_of[a], centre_of[b])
        db = epipolar_descriptors(r[ib], vis[ib], centre_of[a], centre_of[b])
        return np.asarray(cKDTree(db).query(da, k=kq)[1])

    return _partners_per_camera(members, per_camera, nearest)


def _camera_members(cam: np.ndarray) -> dict[Any, np.ndarray]:
    """Image indices of each camera, shape ``(N_c,)`` each, keyed by camera id in sorted order."""
    return {c: np.nonzero(cam == c)[0] for c in np.unique(cam)}


def _partners_per_camera(
    members: dict[Any, np.ndarray], per_camera: int, nearest: Callable[[Any, Any, int], np.ndarray]
) -> np.ndarray:
    """Partner table from ``nearest(a, b, k)``: for each image of camera ``a``, its ``k`` nearest of camera ``b``.

    Args:
        members: Image indices of each camera (:func:`_camera_members`).
        per_camera: Slots given to each other camera.
        nearest: Indices into ``members[b]``, shape ``(len(members[a]), k)`` (or ``(len(members[a]),)`` for k = 1).

    Returns:
        Partner image indices, shape ``(N, (V - 1) * per_camera)`` int64, ``-1`` where a camera has fewer images.
    """
    n = sum(ic.size for ic in members.values())
    out = np.full((n, max(len(members) - 1, 1) * per_camera), -1, dtype=np.int64)
    for a, ia in members.items():
        slot = 0
        for b, ib in members.items():
            if b == a:
                continue
            kq = min(per_camera, ib.size)
            out[ia, slot : slot + kq] = ib[nearest(a, b, kq).reshape(ia.size, kq)]
            slot += per_camera
    return out


def pair_costs(
    C: np.ndarray, r: np.ndarray, rows: np.ndarray, cols: np.ndarray, *, dtype: type = np.float64
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact pseudo-triangulation of image pairs ``(rows[q], cols[q])`` (as the dense path computes it).

    Works on per-component ``(N, J)`` planes of rays, Pluecker moments ``m = C x r`` and ``r . C``, so
    each pair needs only gathers and elementwise products.

    Args:
        C: Camera centre per image, metres, shape ``(N, 3)``.
        r: Unit rays, zero where missing, shape ``(N, J, 3)``.
        rows: First image of each pair, shape ``(P,)``.
        cols: Second image, shape ``(P,)``.
        dtype: Working precision of the per-joint terms (float32 halves memory traffic; see
            ``benchmarks/bench_candidates.py`` for its error).

    Returns:
        ``(cost, convergence, valid, depth)``: mean normalised error over valid joints (``+inf`` if
        none), shape ``(P,)``; mean ``r_i . r_j`` (NaN if none), shape ``(P,)``; valid joints, shape
        ``(P, J)``; depth ``s`` of the closest point along the first image's rays, shape ``(P, J)``.
    """
    p = rows.shape[0]
    j = r.shape[1]
    R: np.ndarray = np.ascontiguousarray(r.transpose(2, 0, 1), dtype=dtype)  # (3, N, J)
    M: np.ndarray = np.ascontiguousarray(np.cross(C[:, None, :], r).transpose(2, 0, 1), dtype=dtype)
    rC = np.einsum("njk,nk->nj", r, C).astype(dtype)
    Cd: np.ndarray = C.astype(dtype)
    cost = np.empty(p)
    conv = np.empty(p)
    valid = np.empty((p, j), dtype=bool)
    depth = np.empty((p, j))
    eps = dtype(_PARALLEL_EPS) if np.dtype(dtype) == np.float64 else dtype(_PARALLEL_EPS_32)
    for q0 in range(0, p, _PAIR_CHUNK):
        i, k = rows[q0 : q0 + _PAIR_CHUNK], cols[q0 : q0 + _PAIR_CHUNK]
        ri, rk = R[:, i], R[:, k]  # (3, P, J)
        b = ri[0] * rk[0] + ri[1] * rk[1] + ri[2] * rk[2]
        Ci, Ck = Cd[i], Cd[k]
        d = rC[i] - (ri[0] * Ck[:, 0, None] + ri[1] * Ck[:, 1, None] + ri[2] * Ck[:, 2, None])
        e = (rk[0] * Ci[:, 0, None] + rk[1] * Ci[:, 1, None] + rk[2] * Ci[:, 2, None]) - rC[k]
        mi, mk = M[:, i], M[:, k]
        triple = mi[0] * rk[0] + mi[1] * rk[1] + mi[2] * rk[2] + ri[0] * mk[0] + ri[1] * mk[1] + ri[2] * mk[2]
        sin2 = 1.0 - b * b
        ok = sin2 > eps
        np.maximum(sin2, eps, out=sin2)
        s = (b * e - d) / sin2
        t = (e - b * d) / sin2
        ok &= (s > 0) & (t > 0)
        err = np.abs(triple) / np.sqrt(sin2) / np.where(ok, s + t, 1.0)
        cnt = ok.sum(1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cost[q0 : q0 + len(i)] = np.where(
                cnt > 0, np.where(ok, err, 0.0).sum(1, dtype=np.float64) / cnt, np.inf
            )
            conv[q0 : q0 + len(i)] = np.where(
                cnt > 0, np.where(ok, b, 0.0).sum(1, dtype=np.float64) / cnt, np.nan
            )
        valid[q0 : q0 + len(i)] = ok
        depth[q0 : q0 + len(i)] = s
    return cost, conv, valid, depth


def _score(C: np.ndarray, r: np.ndarray, cand: np.ndarray, dtype: type) -> tuple[np.ndarray, ...]:
    """Pair costs of the candidate slots ``cand`` (N, M): cost, convergence (N, M), valid, depth (N, M, J)."""
    n, m = cand.shape
    j = r.shape[1]
    rows = np.repeat(np.arange(n), m)
    cols = cand.ravel()
    used = cols >= 0
    cost = np.full(n * m, np.inf)
    conv = np.full(n * m, np.nan)
    valid = np.zeros((n * m, j), dtype=bool)
    depth = np.zeros((n * m, j))
    cost[used], conv[used], valid[used], depth[used] = pair_costs(C, r, rows[used], cols[used], dtype=dtype)
    return cost.reshape(n, m), conv.reshape(n, m), valid.reshape(n, m, j), depth.reshape(n, m, j)


def _pose_partners(X: np.ndarray, cam: np.ndarray, per_camera: int) -> np.ndarray:
    """Nearest images of each other camera under the 3-D pose descriptor ``X.reshape(N, 3 J)``, ``(N, M)``."""
    from scipy.spatial import cKDTree

    flat = X.reshape(X.shape[0], -1)
    members = _camera_members(cam)
    trees = {c: cKDTree(flat[ic]) for c, ic in members.items()}

    def nearest(a: Any, b: Any, kq: int) -> np.ndarray:
        return np.asarray(trees[b].query(flat[members[a]], k=kq)[1])

    return _partners_per_camera(members, per_camera, nearest)


def _new_only(cand: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``new`` with entries already in the same row of ``cand`` (or repeated in ``new``) set to ``-1``."""
    m = cand.shape[1]
    both = np.concatenate([cand, new], axis=1)
    idx = np.argsort(both, axis=1, kind="stable")
    srt = np.take_along_axis(both, idx, axis=1)
    dup = np.zeros_like(both, dtype=bool)
    np.put_along_axis(dup, idx[:, 1:], (srt[:, 1:] == srt[:, :-1]) & (srt[:, 1:] >= 0), axis=1)
    out = np.where(dup[:, m:], -1, new)
    return out[:, (out >= 0).any(0)]


def candidate_pseudo_triangulate(
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    cam_id: np.ndarray,
    *,
    per_camera: int = 12,
    pose_per_camera: int = 8,
    min_angle_deg: float = 30.0,
    dtype: type = np.float32,
) -> CandidatePseudoTriangulation:
    """Pseudo-triangulation restricted to candidate partners: linear memory, ``O(N log N)`` time.

    Costs, the near-parallel demotion for X_init (``min_angle_deg``) and the X_init rules are those of
    :func:`~gttnet.geometry.triangulation.pseudo_triangulate`, with "every other image" replaced by
    "the candidates", all scored exactly. Two rounds: the epipolar-descriptor neighbours of
    :func:`candidate_partners` give a first X_init; then the images nearest under that 3-D pose (a
    ``3 J`` descriptor shared by all cameras, one k-d tree per camera) are added and X_init is redone.

    Args:
        centers: Camera centre of each image in world, metres, shape ``(N, 3)``.
        rays: Viewing rays in world, shape ``(N, J, 3)`` (normalised here; anything where not visible).
        visible: Observed-joint mask, shape ``(N, J)`` bool.
        cam_id: Camera of each image, shape ``(N,)`` int.
        per_camera: Epipolar-descriptor candidates per other camera.
        pose_per_camera: 3-D pose candidates per other camera in the second round (0 skips it).
        min_angle_deg: Near-parallel demotion for X_init (0 = off).
        dtype: Working precision of the pair costs: float32 (measured on 1,440-image captures: costs within
            1.4e-4 of their mean, X_init within 0.01 mm of float64, 40 % faster) or float64 (the dense
            path's costs to rounding).

    Returns:
        A :class:`CandidatePseudoTriangulation`.

    Raises:
        GttNetError: If no candidate pair has a triangulable joint.
    """
    C = np.asarray(centers, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    cam = np.asarray(cam_id)
    n, j = vis.shape
    r_in = np.asarray(rays, dtype=np.float64)
    if C.shape != (n, 3) or r_in.shape != (n, j, 3) or cam.shape != (n,):
        raise ValueError(
            f"expected centers (N, 3), rays (N, J, 3), visible (N, J), cam_id (N,) with N={n}, J={j}; got "
            f"{C.shape}, {r_in.shape}, {vis.shape}, {cam.shape}"
        )
    r = _unit_rays(r_in, vis)
    cand = candidate_partners(C, r, vis, cam, per_camera=per_camera)
    cost, conv, valid, depth = _score(C, r, cand, dtype)
    if pose_per_camera > 0 and np.isfinite(cost).any():
        first = _rank(C, r, vis, cand, cost, conv, valid, depth, min_angle_deg)
        extra = _new_only(cand, _pose_partners(first.X_init, cam, pose_per_camera))
        e_cost, e_conv, e_valid, e_depth = _score(C, r, extra, dtype)
        cand = np.concatenate([cand, extra], 1)
        cost, conv = np.concatenate([cost, e_cost], 1), np.concatenate([conv, e_conv], 1)
        valid, depth = np.concatenate([valid, e_valid], 1), np.concatenate([depth, e_depth], 1)
    if not np.isfinite(cost).any():
        raise GttNetError(
            "pseudo-triangulation found no triangulable joint: need >= 2 cameras sharing a joint"
        )
    return _rank(C, r, vis, cand, cost, conv, valid, depth, min_angle_deg)


def _rank(
    C: np.ndarray,
    r: np.ndarray,
    vis: np.ndarray,
    cand: np.ndarray,
    cost: np.ndarray,
    conv: np.ndarray,
    valid: np.ndarray,
    depth: np.ndarray,
    min_angle_deg: float,
) -> CandidatePseudoTriangulation:
    """Sort each row's slots by cost and build X_init (demoted partners last).

    Only the ``(N, M)`` arrays are reordered; X_init reads the ``(N, M, J)`` ones through a per-slot key.
    """
    n, m = cand.shape
    finite = np.isfinite(cost)
    srt = np.lexsort((cost, ~finite), axis=-1)
    rows = np.arange(n)[:, None]
    pos = np.empty((n, m), dtype=np.int32)
    pos[rows, srt] = np.arange(m, dtype=np.int32)[None, :]
    demoted = np.zeros((n, m), dtype=bool)
    if min_angle_deg > 0:
        demoted = np.abs(np.nan_to_num(conv, nan=0.0)) > np.cos(np.deg2rad(min_angle_deg))
    # X_init visits finite, non-demoted partners by cost, then demoted ones, then the rest.
    key = (pos + m * demoted + 2 * m * ~finite).astype(np.int32)
    X, source = _initial_structure(C, r, vis, cand, valid, depth, key, finite)
    cand, cost, conv = (np.take_along_axis(a, srt, axis=1) for a in (cand, cost, conv))
    return CandidatePseudoTriangulation(partners=cand, cost=cost, convergence=conv, X_init=X, source=source)


def _initial_structure(
    C: np.ndarray,
    r: np.ndarray,
    vis: np.ndarray,
    cand: np.ndarray,
    valid: np.ndarray,
    depth: np.ndarray,
    key: np.ndarray,
    finite: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """X_init over candidate slots, best (lowest ``key``, shape ``(N, M)``) first."""
    n, j = vis.shape
    big = np.int32(np.iinfo(np.int32).max)
    kv = np.where(valid, key[:, :, None], big)  # (N, M, J)
    slot = np.argmin(kv, axis=1)  # (N, J)
    have = np.take_along_axis(kv, slot[:, None, :], axis=1)[:, 0] < big
    s = np.take_along_axis(depth, slot[:, None, :], axis=1)[:, 0]
    src = np.where(have, np.take_along_axis(cand, slot, axis=1), -1)
    X = C[:, None, :] + np.where(have, s, 0.0)[..., None] * np.where(have[..., None], r, 0.0)
    # Fill joints without a triangulation from the best-ranked finite partner that has one.
    nb = np.maximum(cand, 0)
    usable = finite & (cand >= 0)
    kf = np.where(have[nb] & usable[..., None], key[:, :, None], big)
    first_nb = np.argmin(kf, axis=1)
    found = np.take_along_axis(kf, first_nb[:, None, :], axis=1)[:, 0] < big
    donor = np.take_along_axis(nb, first_nb, axis=1)
    out = fill_from_donors(X, have, found, donor)
    out = project_lone(out, C, r, vis & ~have)
    return out, src.astype(np.int64)
