"""Self-assessment of a reconstruction without ground truth: a predicted MPJPE and a per-joint uncertainty.

Every piece of evidence comes from the input and the reconstruction alone:

* **noise** ``sigma_px``: the capture's own 2-D keypoint noise (:func:`gttnet.geometry.noise.stream_noise_px`)
  along each camera's frames, in the given stream order, else in the order the method recovered;
* **residual** ``residual_px``: how far the reconstruction reprojects from the 2-D observations (robust
  per-axis spread, pixels). A residual far above the noise means the structure does not explain the images
  (wrong clocks, a wrong frame rate, a wrong order);
* **lateral error** ``lateral_mm``: the residual (or the noise, whichever is larger) at each joint's depth
  (``px * depth / f``), millimetres;
* **geometry** ``geometry_mm``: the depth error the noise alone leaves, given the angle between a joint's ray
  and the rays of the same joint in the images nearest in the recovered order from other cameras
  (``noise_mm / sin(angle)``): a reconstruction can reproject perfectly yet be wrong in depth where no
  other camera looks at the same moment;
* **roughness** ``roughness_mm``: the second difference of the 3-D joints along the recovered order
  (what the motion plus the errors leave between neighbouring images);
* **weak stretches** ``weak_fraction``: the share of the points (image, joint) that fewer than
  :data:`MIN_VIEWS` cameras see at nearby moments (the subject leaving the views, long occlusions). Nothing
  triangulates them: only the motion before and after places them, and the residual, held-out and roughness
  terms, computed where the images see the subject, cannot see their error. Their own term ``weak_mm``
  combines how far the method's points there are from the interpolation of the observed neighbours
  (``weak_offset_mm``) with how far the reconstruction's own observed motion leaves such an interpolation
  over gaps of the same length (``weak_gap_mm``: a held-out prediction across the gap);
* **contradicted images** ``outlier_fraction``: the share of the images whose prediction from the other
  cameras misses by over :data:`OUTLIER_HOLDOUT` times the noise against most of them (:func:`_contradicted`),
  and that miss's mean ``outlier_mm``: images the other cameras contradict (a second person handed in by the detector, a mis-detection, a wrong
  clock). Medians over all points cannot see a tenth of the images being far off; this term does.

:data:`CALIBRATION` maps their logarithms to the logarithm of the MPJPE (a small least-squares fit, see
its comment for the command that produced it). The per-joint uncertainty spreads the predicted error over
the joints in proportion to each joint's own lateral and depth terms. Ground truth never reaches this
module: it takes only :class:`~gttdata.capture.views.Observations` and a reconstruction.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from gttnet.geometry.noise import stream_noise_px

if TYPE_CHECKING:
    from gttdata.capture.views import Observations
    from gttnet.methods import Reconstruction

__all__ = ["CALIBRATION", "FEATURES", "assess", "features", "joint_uncertainty_mm", "predict_mm", "weak_mm"]

#: The evidence of the log-linear part, in the order of :data:`CALIBRATION`'s slopes (each enters as its
#: natural logarithm): the noise at the joints' depth, the held-out error and the roughness over it.
FEATURES = ("noise_mm", "holdout_ratio", "roughness_ratio")
#: Further scalars of :func:`features` reported with the prediction (``excess_mm`` and ``blind_mm`` enter
#: :func:`predict_mm` as their own terms).
EXTRAS = (
    "sigma_px",
    "residual_px",
    "excess",
    "excess_mm",
    "lateral_mm",
    "geometry_mm",
    "roughness_mm",
    "holdout_mm",
    "blind_fraction",
    "blind_mm",
    "weak_fraction",
    "weak_offset_mm",
    "weak_gap_mm",
    "weak_mm",
    "longest_unseen_images",
    "outlier_fraction",
    "outlier_mm",
)
#: Added to ``roughness_mm / noise_mm`` before the logarithm (smooth trajectories reach 0).
ROUGHNESS_FLOOR = 0.05

#: ``log(base_mm) = intercept + sum(slope_i * log(feature_i))`` over :data:`FEATURES`; the prediction is
#: ``hypot(base_mm, excess_factor * excess_mm)`` (see :func:`predict_mm`). Intercept and slopes fitted by
#: ``python benchmarks/bench_auto.py --fit runs/bench_auto/fit.jsonl`` on the rows of ``python
#: benchmarks/bench_auto.py --recipes recipes/gttdata/paper.yaml,recipes/gttdata/default.yaml,``
#: ``recipes/gttdata/hands.yaml,recipes/gttdata/topologies.yaml --split val --n-seq 5 --no-auto --rows
#: runs/bench_auto/fit.jsonl`` (217 reconstructions of 20 captures, every candidate method under every
#: sequencing condition: log residual std 0.223, 98.2 % within [0.5x, 2x]). ``excess_factor`` and
#: ``interval_factor`` (the per-point bound's multiple of the spread MPJPE, for an 80 % rate) were chosen on
#: the ``val`` half of the out-of-distribution cells (``recipes/gttdata/ood/``); docs/METHOD.md has the
#: calibration measured on their ``test`` half. ``weak_gap_factor`` and ``outlier_factor`` (2026-12-06):
#: ``python benchmarks/bench_auto.py --fit runs/ood26/fit_all.jsonl`` on the rows of ``--recipes
#: recipes/gttdata/paper.yaml,recipes/gttdata/default.yaml,recipes/gttdata/hands.yaml,``
#: ``recipes/gttdata/topologies.yaml --split val --n-seq 2 --no-auto`` and ``--cells walk_1px_drop30`` /
#: ``--cells second_person --split val --n-seq 3 --no-auto`` (68 reconstructions with weak stretches or
#: contradicted images: 88.2 % within [0.5x, 2x]; the intercept and slopes above were kept).
CALIBRATION: dict[str, Any] = {
    "intercept": 0.0417,
    "slopes": [1.0793, 0.5955, 0.2946],
    "excess_factor": 2.0,
    "interval_factor": 1.35,
    "interval_rate": 0.8,
    "weak_gap_factor": 0.1,
    "outlier_factor": 1.5,
}

#: Images on each side of an image, in the recovered order, whose rays count for its joints' geometry.
NEIGHBOURS = 4
#: The smallest ray angle's sine counted (a joint no other camera sees nearby gets this: ~3 degrees).
MIN_SIN = 0.05
#: A point is weakly observed where fewer cameras than this see its joint among the images nearest in the
#: recovered order (about one frame of every camera on each side).
MIN_VIEWS = 2
#: An image contradicts the other cameras where its held-out error is over this many times the noise (mm).
OUTLIER_HOLDOUT = 5.0
#: An image sees the subject when it observes at least this many joints (``longest_unseen_images``).
MIN_SEEN_JOINTS = 3
#: The residual of a 2-D Gaussian's radius at its median, in units of the per-axis std: sqrt(2 ln 2).
_RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))


def _recovered_rank(obs: Observations, rec: Reconstruction) -> np.ndarray | None:
    """Each image's rank in time: the method's recovered order, else the timestamps, else None."""
    if rec.order is not None:
        return np.asarray(rec.order)
    if obs.timestamp_s is not None:
        return np.argsort(np.argsort(np.asarray(obs.timestamp_s), kind="stable"), kind="stable")
    return None


def _stream_index(obs: Observations, rank: np.ndarray | None) -> np.ndarray | None:
    """Each image's frame index within its camera: given, else the recovered rank within the camera."""
    if obs.stream_index is not None:
        return np.asarray(obs.stream_index)
    if rank is None:
        return None
    si = np.zeros(obs.n_images, dtype=np.int64)
    for c in np.unique(obs.cam_id):
        idx = np.flatnonzero(obs.cam_id == c)
        si[idx[np.argsort(rank[idx], kind="stable")]] = np.arange(idx.size)
    return si


def _reprojection(obs: Observations, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Residual (px), depth (m) and mm-per-px of every (image, joint), each shape ``(N, J)``; NaN where unused."""
    T = np.asarray(obs.cam_from_world, dtype=np.float64)
    Xc = np.einsum("nab,njb->nja", T[:, :3, :3], X) + T[:, None, :3, 3]
    z = Xc[..., 2]
    K = np.asarray(obs.K, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        uv = np.einsum("nab,njb->nja", K[:, :2, :3], Xc) / z[..., None]
    ok = np.asarray(obs.visible, dtype=bool) & np.isfinite(uv).all(axis=-1) & (z > 0)
    kp = np.asarray(obs.keypoints_px, dtype=np.float64)
    r = np.where(ok, np.linalg.norm(np.where(ok[..., None], uv - kp, 0.0), axis=-1), np.nan)
    f = 0.5 * (K[:, 0, 0] + K[:, 1, 1])
    mm_per_px = np.where(ok, 1000.0 * z / f[:, None], np.nan)
    return r, np.where(ok, z, np.nan), mm_per_px


def _best_sine(obs: Observations, rank: np.ndarray | None) -> np.ndarray:
    """Largest sine of the angle between each joint's ray and the same joint's ray in a neighbouring image.

    Neighbours are the :data:`NEIGHBOURS` images on each side in the recovered order taken by other
    cameras; shape ``(N, J)``, :data:`MIN_SIN` where none sees the joint (or no order was recovered).
    """
    n, j = obs.visible.shape
    best = np.full((n, j), MIN_SIN)
    if rank is None or n < 2:
        return best
    d = obs.rays()
    vis = np.asarray(obs.visible, dtype=bool)
    seq = np.argsort(rank, kind="stable")
    cam = np.asarray(obs.cam_id)[seq]
    for off in range(1, NEIGHBOURS + 1):
        a, b = seq[:-off], seq[off:]
        other = (cam[:-off] != cam[off:])[:, None] & vis[a] & vis[b]
        s = np.linalg.norm(np.cross(d[a], d[b]), axis=-1)
        s = np.where(other, s, 0.0)
        best[a] = np.maximum(best[a], s)
        best[b] = np.maximum(best[b], s)
    return best


def _holdout(obs: Observations, X: np.ndarray, rank: np.ndarray | None, s: np.ndarray) -> np.ndarray:
    """Held-out prediction error of every (image, joint), millimetres at the joint's depth, shape ``(N, J)``.

    Each image is left out and predicted from the nearest images of other cameras before and after it in
    the recovered order (linear in rank); the prediction is reprojected into the left-out image. A point
    wrong in depth along its own ray reprojects perfectly in its own image but lands off the ray seen from
    another camera, so this measures what the own-image residual cannot. NaN where no prediction exists.
    """
    n = obs.n_images
    out = np.full(obs.visible.shape, np.nan)
    if rank is None or n < 3:
        return out
    seq = np.argsort(rank, kind="stable")
    cam = np.asarray(obs.cam_id)[seq]
    pos = np.arange(n)
    prev = np.full(n, -1)
    nxt = np.full(n, -1)
    for c in np.unique(cam):  # nearest position of a camera other than c before / after each position
        other = np.flatnonzero(cam != c)
        if other.size == 0:
            continue
        mine = pos[cam == c]
        k = np.searchsorted(other, mine)
        prev[mine] = np.where(k > 0, other[np.maximum(k - 1, 0)], -1)
        nxt[mine] = np.where(k < other.size, other[np.minimum(k, other.size - 1)], -1)
    ok = (prev >= 0) & (nxt >= 0)
    if not ok.any():
        return out
    p, a, b = pos[ok], prev[ok], nxt[ok]
    w = ((p - a) / (b - a))[:, None, None]
    Xh = np.full(X.shape, np.nan)
    Xh[seq[p]] = (1.0 - w) * X[seq[a]] + w * X[seq[b]]
    r, _z, _s = _reprojection(obs, Xh)
    return r * s / _RAYLEIGH_MEDIAN


def _contradicted(
    obs: Observations, X: np.ndarray, rank: np.ndarray | None, s: np.ndarray, noise_mm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Images the other cameras contradict, shape ``(N,)`` bool, and their per-point miss (mm), ``(N, J)``.

    Each image is predicted from each other camera separately (linear in rank between that camera's
    nearest images before and after it) and reprojected into it; the image's miss against that camera is
    the median over its joints, in mm at their depth. An image is contradicted where its miss exceeds
    :data:`OUTLIER_HOLDOUT` times the noise against more than half of the cameras that predict it: a bad
    image disagrees with every camera, while its neighbours disagree only with the bad image's camera.
    """
    n, j = obs.visible.shape
    none = np.zeros(n, dtype=bool), np.full((n, j), np.nan)
    if rank is None or n < 3:
        return none
    seq = np.argsort(rank, kind="stable")
    cam = np.asarray(obs.cam_id)[seq]
    pos = np.arange(n)
    cams = np.unique(cam)
    misses, points = [], []
    for c in cams:
        theirs = pos[cam == c]
        if theirs.size < 2:
            continue
        k = np.searchsorted(theirs, pos)
        ok = (k > 0) & (k < theirs.size) & (cam != c)
        if not ok.any():
            continue
        p, a, b = pos[ok], theirs[k[ok] - 1], theirs[k[ok]]
        w = ((p - a) / (b - a))[:, None, None]
        Xh = np.full(X.shape, np.nan)
        Xh[seq[p]] = (1.0 - w) * X[seq[a]] + w * X[seq[b]]
        r, _z, _s = _reprojection(obs, Xh)
        pt = r * s / _RAYLEIGH_MEDIAN
        with np.errstate(invalid="ignore"):
            misses.append(np.array([_nanmedian(row) for row in pt]))
        points.append(pt)
    if len(misses) < 1:
        return none
    m = np.stack(misses)
    with np.errstate(invalid="ignore"):
        high = (m > OUTLIER_HOLDOUT * noise_mm).sum(axis=0)
    known = np.isfinite(m).sum(axis=0)
    flag = (known > 0) & (high > 0.5 * known)
    miss = np.full((n, j), np.nan)
    if flag.any():
        pts = np.stack(points)[:, flag]  # (cameras, flagged images, J)
        seen = np.isfinite(pts).any(axis=0)
        sub = np.full(pts.shape[1:], np.nan)
        sub[seen] = np.nanmedian(pts[:, seen], axis=0)
        miss[flag] = sub
    return flag, miss


def _blind_rows(obs: Observations) -> np.ndarray:
    """Images with no observed joint, shape ``(N,)`` bool: only their neighbours in time can place them.

    Under ``partial``, an image of a camera that observes joints in at least three images is placed by
    its neighbours in the stream and does not count; a camera with fewer (a blind camera) does.
    """
    blind = np.asarray(~np.asarray(obs.visible, dtype=bool).any(axis=1), dtype=bool)
    if obs.sequencing == "partial" and blind.any():
        cam = np.asarray(obs.cam_id)
        seen = {int(c): int((~blind[cam == c]).sum()) for c in np.unique(cam)}
        blind = blind & np.array([seen[int(c)] < 3 for c in cam])
    return blind


def _blind(obs: Observations, X: np.ndarray) -> tuple[float, float]:
    """Fraction of the images without observations (:func:`_blind_rows`) and their expected error, mm.

    Nothing observed places their joints. With timestamps (``full``) the error is the distance of the
    method's points there from the interpolation, in time, of the nearest observed images before and after
    (a method that ignores the timestamps leaves them anywhere). Without, where such an image truly is
    within the motion is unknown: the RMS distance of its points from each joint's mean over the observed
    images, in quadrature with that joint's spread over time.
    """
    blind = _blind_rows(obs)
    if not blind.any() or blind.all():
        return 0.0, 0.0
    with np.errstate(invalid="ignore"):
        if obs.sequencing == "full" and obs.timestamp_s is not None:
            t = np.asarray(obs.timestamp_s, dtype=np.float64)
            seen_idx = np.flatnonzero(~blind)
            seen_idx = seen_idx[np.argsort(t[seen_idx], kind="stable")]
            ts = t[seen_idx]
            tb = t[blind]
            k = np.clip(np.searchsorted(ts, tb), 1, ts.size - 1)
            a, b = seen_idx[k - 1], seen_idx[k]
            w = np.clip((tb - t[a]) / np.maximum(t[b] - t[a], 1e-12), 0.0, 1.0)[:, None, None]
            ref = (1.0 - w) * X[a] + w * X[b]
            e = np.linalg.norm(X[blind] - ref, axis=-1)
        else:
            seen = X[~blind]
            mean = np.nanmean(seen, axis=0)
            spread2 = np.nanmean(np.sum((seen - mean) ** 2, axis=-1), axis=0)
            d2 = np.sum((X[blind] - mean) ** 2, axis=-1)
            e = np.sqrt(d2 + spread2[None, :])
    return float(blind.mean()), 1000.0 * float(np.nanmean(e)) if np.isfinite(e).any() else 0.0


def _views(obs: Observations, seq: np.ndarray) -> np.ndarray:
    """How many cameras see each joint among the images near each image in the order ``seq``, shape ``(N, J)``.

    ``seq`` lists the images in their recovered order; the window is one image per camera on each side
    (``n_cameras`` positions each way), so at every moment each camera has about one frame in it.
    """
    n, j = obs.visible.shape
    cam = np.asarray(obs.cam_id)[seq]
    vis = np.asarray(obs.visible, dtype=bool)[seq]
    cams = np.unique(cam)
    w = int(cams.size)
    lo = np.clip(np.arange(n) - w, 0, n)
    hi = np.clip(np.arange(n) + w + 1, 0, n)
    count = np.zeros((n, j), dtype=np.int64)
    for c in cams:
        cs = np.concatenate([np.zeros((1, j), np.int64), np.cumsum((cam == c)[:, None] & vis, axis=0)])
        count += (cs[hi] - cs[lo]) > 0
    out = np.empty_like(count)
    out[seq] = count
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of every maximal run of True in a 1-D mask (``stop`` exclusive)."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def _gap_mm(x: np.ndarray, strong: np.ndarray, h: int, base: int) -> float:
    """Median miss, mm, of predicting the reconstruction's own strong points across a gap of ``h`` positions.

    ``x`` is one joint's track in the recovered order, shape ``(N, 3)``, metres. ``base == 0`` (a gap between
    two observed stretches): each strong point from the mean of the strong points ``h`` before and after it
    (the middle of a gap of ``2h - 1``). ``base > 0`` (a gap at an end of the capture): linear
    extrapolation from the strong points ``h`` and ``h + base`` after it. NaN where no such points.
    """
    n = x.shape[0]
    if base == 0:
        if n <= 2 * h:
            return float("nan")
        q = np.arange(h, n - h)
        ok = strong[q] & strong[q - h] & strong[q + h]
        miss = x[q] - 0.5 * (x[q - h] + x[q + h])
    else:
        if n <= h + base:
            return float("nan")
        q = np.arange(0, n - h - base)
        ok = strong[q] & strong[q + h] & strong[q + h + base]
        miss = x[q] - x[q + h] - (h / base) * (x[q + h] - x[q + h + base])
    d = np.linalg.norm(miss[ok], axis=-1)
    d = d[np.isfinite(d)]
    return 1000.0 * float(np.median(d)) if d.size else float("nan")


def _binned(h: int) -> int:
    """``h`` rounded to a power of 1.25 (at most a few dozen gap lengths per joint on any recording).

    Example:
        >>> [_binned(h) for h in (1, 2, 3, 7, 100)]
        [1, 2, 3, 7, 108]
    """
    return max(1, int(round(1.25 ** round(math.log(max(h, 1)) / math.log(1.25)))))


def _weak(
    obs: Observations, X: np.ndarray, rank: np.ndarray | None, skip: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weakly observed points and, per point, their offset and gap terms (mm), each shape ``(N, J)``.

    A point is weak where fewer than :data:`MIN_VIEWS` cameras see its joint near it in the recovered order
    (:func:`_views`); images in ``skip`` (blind rows, with their own term) are left out. Along each joint's
    track, every maximal run of weak points is placed only by its strong neighbours: the offset is each
    point's distance from the linear interpolation of the run's two neighbours (from the one neighbour at an
    end of the capture), the gap term :func:`_gap_mm` of the run's length. Without an order nothing is
    weak (no moment is known; images without observations count as blind rows).
    """
    n, j = obs.visible.shape
    weak = np.zeros((n, j), dtype=bool)
    offset = np.zeros((n, j))
    gap = np.zeros((n, j))
    finite = np.isfinite(X).all(axis=-1)
    if rank is None:
        return weak, offset, gap
    seq = np.argsort(rank, kind="stable")
    keep = seq[~skip[seq]]
    if keep.size < 3:
        return weak, offset, gap
    views = _views(obs, seq)[keep]
    Xs = X[keep]
    ok = finite[keep]
    base = 2 * int(np.unique(obs.cam_id).size)  # about two frames of each camera: the velocity's baseline
    cache: dict[tuple[int, int, int], float] = {}
    for k in range(j):
        w = (views[:, k] < MIN_VIEWS) & ok[:, k]
        if not w.any():
            continue
        strong = ok[:, k] & ~w
        if not strong.any():
            continue
        for a, b in _runs(w):
            lo, hi = a - 1, b  # the strong neighbours before and after the run (-1 / n: none)
            while lo >= 0 and not strong[lo]:
                lo -= 1
            while hi < keep.size and not strong[hi]:
                hi += 1
            pos = np.arange(a, b)
            if lo >= 0 and hi < keep.size:
                t = ((pos - lo) / (hi - lo))[:, None]
                ref = (1.0 - t) * Xs[lo, k] + t * Xs[hi, k]
                key = (k, _binned((hi - lo + 1) // 2), 0)
            elif lo < 0 and hi >= keep.size:
                continue
            else:  # at an end: linear extrapolation from the stretch's first observed images
                sign = 1 if lo < 0 else -1
                anchor = hi if lo < 0 else lo
                far = np.flatnonzero(strong)
                far = far[sign * (far - anchor) >= base]
                if far.size == 0:
                    continue
                second = int(far[0] if sign > 0 else far[-1])
                v = (Xs[anchor, k] - Xs[second, k]) / abs(second - anchor)
                ref = Xs[anchor, k] + np.abs(pos - anchor)[:, None] * v
                key = (k, _binned(max((b - a + 1) // 2, 1)), base)
            if key not in cache:
                x_k = Xs[:, k] if key[2] == 0 or lo < 0 else Xs[::-1, k]
                st = strong if key[2] == 0 or lo < 0 else strong[::-1]
                cache[key] = _gap_mm(x_k, st, key[1], key[2])
            idx = keep[pos]
            weak[idx, k] = True
            offset[idx, k] = 1000.0 * np.linalg.norm(Xs[pos, k] - ref, axis=-1)
            gap[idx, k] = cache[key]
    return weak, offset, np.nan_to_num(gap, nan=0.0)


def _longest_unseen(obs: Observations, rank: np.ndarray | None) -> int:
    """The longest run of one camera's consecutive images that see fewer than :data:`MIN_SEEN_JOINTS` joints.

    Along each camera's frames (given, else in the recovered order); 0 without any order.
    """
    si = _stream_index(obs, rank)
    if si is None:
        return 0
    seen = np.asarray(obs.visible, dtype=bool).sum(axis=1) >= MIN_SEEN_JOINTS
    cam = np.asarray(obs.cam_id)
    best = 0
    for c in np.unique(cam):
        idx = np.flatnonzero(cam == c)
        idx = idx[np.argsort(si[idx], kind="stable")]
        runs = _runs(~seen[idx])
        best = max([best] + [b - a for a, b in runs])
    return best


def _nanmedian(a: np.ndarray) -> float:
    v = np.asarray(a, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if v.size else float("nan")


def features(
    obs: Observations, rec: Reconstruction, *, noise_px: float | None = None, order: np.ndarray | None = None
) -> dict[str, Any]:
    """The evidence of :data:`FEATURES` for one reconstruction, plus per-joint terms.

    Args:
        obs: The observations the reconstruction was made from (the same image order).
        rec: The reconstruction, ``points3d`` of shape ``(N, J, 3)`` in metres.
        noise_px: The capture's 2-D noise read along other streams (e.g. another method's recovered
            order), pixels; the smaller of it and the estimate along this reconstruction's own order is
            used (a wrong order only adds to the frame-to-frame differences the noise is read from).
        order: A rank of the images in time to read the evidence along (shape ``(N,)``), in place of the
            reconstruction's own recovered order: e.g. the order whose streams read the least noise.

    Returns:
        Scalars ``sigma_px``, ``residual_px`` and the :data:`FEATURES` (millimetres, ``excess`` a ratio),
        and ``per_joint_mm`` (shape ``(J,)``) / ``per_point_mm`` (shape ``(N, J)``): each joint's
        quadrature of its lateral and depth terms (relative weights; NaN where not reconstructed).
    """
    X = np.asarray(rec.points3d, dtype=np.float64)
    rank = _recovered_rank(obs, rec) if order is None else np.asarray(order)
    r, _z, s = _reprojection(obs, X)
    si = _stream_index(obs, rank)
    sigma = None
    if si is not None:
        sigma = stream_noise_px(obs.keypoints_px, obs.visible, obs.cam_id, si)
    if noise_px is not None and math.isfinite(noise_px) and (sigma is None or noise_px < sigma):
        sigma = float(noise_px)
    residual = _nanmedian(r) / _RAYLEIGH_MEDIAN
    if sigma is None or not math.isfinite(sigma):
        sigma_eff = residual if math.isfinite(residual) else 1.0
    else:
        sigma_eff = sigma
    sigma_eff = max(sigma_eff, 0.1)
    sine = _best_sine(obs, rank)
    lateral_pt = np.maximum(np.nan_to_num(r, nan=0.0) / _RAYLEIGH_MEDIAN, sigma_eff) * s
    depth_pt = sigma_eff * s / sine
    point = np.sqrt(lateral_pt**2 + depth_pt**2)
    finite = np.isfinite(X).all(axis=-1)
    point = np.where(finite, point, np.nan)
    with np.errstate(invalid="ignore"):
        per_joint = np.array([_nanmedian(point[:, k]) for k in range(point.shape[1])])
        per_point = point.copy()
    # images that do not see a joint: the joint's median over the images that do
    per_point = np.where(np.isfinite(per_point), per_point, per_joint[None, :])
    per_point = np.where(finite, per_point, np.nan)
    rough = float("nan")
    if rank is not None and obs.n_images >= 3:
        seq = np.argsort(rank, kind="stable")
        d2 = X[seq[:-2]] - 2.0 * X[seq[1:-1]] + X[seq[2:]]
        rough = 1000.0 * _nanmedian(np.linalg.norm(d2, axis=-1))
    mm = _nanmedian(s)
    hold = _holdout(obs, X, rank, s)
    blind_frac, blind_mm = _blind(obs, X)
    blind_rows = _blind_rows(obs)
    weak, w_off, w_gap = _weak(obs, X, rank, blind_rows)
    outlier, out_pt = _contradicted(obs, X, rank, s, float(sigma_eff * mm))
    outlier &= ~blind_rows
    with np.errstate(invalid="ignore"):
        img_miss = np.array([_nanmedian(row) for row in out_pt])
    out = {
        "sigma_px": None if sigma is None else float(sigma),
        "residual_px": float(residual),
        "noise_mm": float(sigma_eff * mm),
        "lateral_mm": _nanmedian(lateral_pt),
        "geometry_mm": _nanmedian(depth_pt),
        "roughness_mm": rough,
        "excess": float(max(residual / sigma_eff, 1.0)) if math.isfinite(residual) else float("nan"),
        "excess_mm": float(math.sqrt(max(residual**2 - sigma_eff**2, 0.0)) * mm)
        if math.isfinite(residual)
        else 0.0,
        "holdout_mm": _nanmedian(hold),
        "holdout_ratio": _nanmedian(hold) / float(sigma_eff * mm),
        "roughness_ratio": rough / float(sigma_eff * mm) + ROUGHNESS_FLOOR,
        "blind_fraction": blind_frac,
        "blind_mm": blind_mm,
        "blind_rows": blind_rows,
        "weak_fraction": float(weak.mean()),
        "weak_offset_mm": _rms(w_off[weak]),
        "weak_gap_mm": _rms(w_gap[weak]),
        "longest_unseen_images": _longest_unseen(obs, rank),
        "outlier_fraction": float(outlier.mean()),
        "outlier_mm": float(np.nanmean(img_miss[outlier])) if outlier.any() else 0.0,
        "outlier_rows": outlier,
        "outlier_point_mm": np.where(outlier[:, None], out_pt, np.nan),
        "weak_points": weak,
        "weak_offset_point_mm": w_off,
        "weak_gap_point_mm": w_gap,
        "per_joint_mm": per_joint,
        "per_point_mm": per_point,
    }
    out["weak_mm"] = weak_mm(out)
    return out


def _rms(v: np.ndarray) -> float:
    v = np.asarray(v, dtype=np.float64)
    v = v[np.isfinite(v)]
    return float(np.sqrt(np.mean(v**2))) if v.size else 0.0


def weak_mm(feats: dict[str, Any], calibration: dict[str, Any] | None = None) -> float:
    """The expected error of the weakly observed points, mm: offset and scaled gap term in quadrature.

    Example:
        >>> weak_mm({"weak_offset_mm": 30.0, "weak_gap_mm": 40.0}, {"weak_gap_factor": 1.0})
        50.0
    """
    cal = CALIBRATION if calibration is None else calibration
    off = float(feats.get("weak_offset_mm") or 0.0)
    gap = float(feats.get("weak_gap_mm") or 0.0)
    return float(math.hypot(off, float(cal.get("weak_gap_factor", 1.0)) * gap))


def predict_mm(feats: dict[str, Any], calibration: dict[str, Any] | None = None) -> float:
    """The calibrated MPJPE prediction, millimetres, from :func:`features`' scalars (NaN features count as 1).

    The log-linear model covers the images with observations, in quadrature with ``excess_factor`` times
    the residual beyond the noise (``excess_mm``: what the structure fails to explain, at the joints'
    depth); untimed images without any observation (a blind camera) count with their own term, weighted
    by their share of the images, and so do the weakly observed points (:func:`weak_mm`, weighted by their
    share of the points) and the images the other cameras contradict (``outlier_factor`` times their
    held-out error, weighted by their share of the images).
    """
    cal = CALIBRATION if calibration is None else calibration
    logv = 0.0 + float(cal["intercept"])
    for name, slope in zip(FEATURES, cal["slopes"], strict=True):
        v = feats.get(name)
        v = 1.0 if v is None or not math.isfinite(float(v)) or float(v) <= 0 else float(v)
        logv += float(slope) * math.log(max(v, 1e-3))
    seen = math.hypot(math.exp(logv), float(cal["excess_factor"]) * float(feats.get("excess_mm") or 0.0))
    b = float(feats.get("blind_fraction") or 0.0)
    w = float(feats.get("weak_fraction") or 0.0)
    o = float(feats.get("outlier_fraction") or 0.0)
    weak = weak_mm(feats, cal) if w > 0 else 0.0
    out = float(cal.get("outlier_factor", 1.0)) * float(feats.get("outlier_mm") or 0.0)
    rest = max(1.0 - b - w - o, 0.0)
    return float(rest * seen + b * float(feats.get("blind_mm") or 0.0) + w * weak + o * out)


def joint_uncertainty_mm(
    feats: dict[str, Any], expected_mm: float, calibration: dict | None = None
) -> np.ndarray:
    """Per-point uncertainty, millimetres, shape ``(N, J)``, NaN where the joint is not reconstructed.

    The bound each point's 3-D error should stay below at :data:`CALIBRATION`'s ``interval_rate``.

    The predicted MPJPE of the well observed points is spread over them in proportion to each point's own
    lateral and depth terms; a weakly observed point gets its own offset and gap terms (:func:`weak_mm`),
    a blind image's point the blind term; all scaled by the calibrated interval factor.
    """
    cal = CALIBRATION if calibration is None else calibration
    p = np.asarray(feats["per_point_mm"], dtype=np.float64).copy()
    blind = np.asarray(feats.get("blind_rows", np.zeros(p.shape[0], bool)), dtype=bool)
    weak = np.asarray(feats.get("weak_points", np.zeros(p.shape, bool)), dtype=bool) & ~blind[:, None]
    seen = p[
        ~blind[:, None] & ~weak & ~np.asarray(feats.get("outlier_rows", np.zeros(p.shape[0], bool)))[:, None]
    ]
    m = float(np.nanmean(seen)) if np.isfinite(seen).any() else float("nan")
    if not math.isfinite(m) or m <= 0:
        return np.full(p.shape, np.nan)
    b = float(feats.get("blind_fraction") or 0.0)
    w = float(feats.get("weak_fraction") or 0.0)
    o = float(feats.get("outlier_fraction") or 0.0)
    o_mm = float(cal.get("outlier_factor", 1.0)) * float(feats.get("outlier_mm") or 0.0)
    rest = expected_mm - b * float(feats.get("blind_mm") or 0.0) - (w * weak_mm(feats, cal) if w > 0 else 0.0)
    observed_mm = (rest - o * o_mm) / max(1.0 - b - w - o, 1e-9)
    out = p * max(observed_mm, 0.0) / m
    outlier = np.asarray(feats.get("outlier_rows", np.zeros(p.shape[0], bool)), dtype=bool)
    if outlier.any():
        own = float(cal.get("outlier_factor", 1.0)) * np.asarray(feats["outlier_point_mm"], dtype=np.float64)
        fill = np.where(np.isfinite(own), own, o_mm)
        out[outlier] = np.where(np.isfinite(p[outlier]), np.maximum(fill[outlier], out[outlier]), np.nan)
    if weak.any():
        off = np.asarray(feats["weak_offset_point_mm"], dtype=np.float64)
        gap = np.asarray(feats["weak_gap_point_mm"], dtype=np.float64)
        own = np.hypot(off, float(cal.get("weak_gap_factor", 1.0)) * gap)
        out[weak] = np.where(np.isfinite(p[weak]), np.maximum(own[weak], out[weak]), np.nan)
    out[blind] = np.where(np.isfinite(p[blind]), float(feats.get("blind_mm") or 0.0), np.nan)
    return float(cal["interval_factor"]) * out


def _reasons(f: dict[str, Any], expected: float) -> list[str]:
    """Plain-language reasons for the prediction (the terms that dominate it)."""
    out = []
    if f["sigma_px"] is None:
        out.append("the 2-D noise could not be measured (streams too short or no order): residual used")
    if f["excess"] > 2.0:
        out.append(
            f"the reconstruction reprojects {f['residual_px']:.1f} px from the images, {f['excess']:.1f}x the "
            "capture's noise: the structure does not explain the images (wrong clocks, rate or order?)"
        )
    if f["geometry_mm"] > 3.0 * f["noise_mm"]:
        out.append(
            f"weak triangulation: joints are rarely seen by another camera at nearby moments "
            f"(depth term {f['geometry_mm']:.0f} mm against {f['noise_mm']:.1f} mm lateral noise)"
        )
    w = float(f.get("weak_fraction") or 0.0)
    if w > 0.0 and w * float(f.get("weak_mm") or 0.0) > 0.25 * expected:
        gap = int(f.get("longest_unseen_images") or 0)
        why = (
            f"the longest stretch of one camera's images without the subject is {gap} images"
            if gap >= MIN_SEEN_JOINTS
            else "the images do see the subject: the recovered clocks or order may put views of one moment apart"
        )
        out.append(
            f"{w:.0%} of the joints' positions are seen by fewer than {MIN_VIEWS} cameras at nearby moments "
            f"({why}): only the motion around them places them, expected error there {f['weak_mm']:.0f} mm"
        )
    o = float(f.get("outlier_fraction") or 0.0)
    if o > 0.0 and o * float(f.get("outlier_mm") or 0.0) > 0.25 * expected:
        out.append(
            f"{o:.0%} of the images are contradicted by the other cameras (held-out error {f['outlier_mm']:.0f} mm, "
            f"over {OUTLIER_HOLDOUT:g}x the noise): another person handed in by the detector, mis-detections "
            "or wrong clocks?"
        )
    if not out:
        out.append("residual at the noise floor and good triangulation angles")
    return out


def assess(
    obs: Observations, rec: Reconstruction, *, noise_px: float | None = None, order: np.ndarray | None = None
) -> tuple[dict[str, Any], np.ndarray]:
    """Self-assessment of ``rec``: the ``quality`` summary and the per-point uncertainty.

    Args:
        obs: The observations the reconstruction was made from.
        rec: The reconstruction.
        noise_px: The capture's noise read along other streams, pixels (see :func:`features`).
        order: The time order to read the evidence along (see :func:`features`).

    Returns:
        ``(quality, uncertainty)``: ``quality`` is JSON-serialisable with ``expected_error_mm`` (predicted
        MPJPE, mm), ``reasons`` (list of strings) and the evidence (``sigma_px``, ``residual_px``,
        ``noise_mm``, ``lateral_mm``, ``geometry_mm``, ``roughness_mm``, ``excess``);
        ``uncertainty`` has shape ``(N, J)``, millimetres (:func:`joint_uncertainty_mm`).
    """
    f = features(obs, rec, noise_px=noise_px, order=order)
    expected = predict_mm(f)
    unc = joint_uncertainty_mm(f, expected)
    q: dict[str, Any] = {"expected_error_mm": round(expected, 3), "reasons": _reasons(f, expected)}
    for k in (*EXTRAS, *FEATURES):
        v = f[k]
        q[k] = None if v is None or not math.isfinite(float(v)) else round(float(v), 4)
    q["interval_rate"] = float(CALIBRATION["interval_rate"])
    return q, unc
