"""Several people in unsynchronized cameras: who is who, across views and through time.

A detector reports every person it finds in every frame, in no particular order. Before a subject can be
reconstructed, each of its detections must be found in every camera. With synchronized cameras the usual
way is to match people frame by frame across views; here no two cameras share an instant, so the
association works on tracks instead:

1. **Tracks in each camera** (:func:`track_camera`). Detections of consecutive frames are linked by an
   optimal assignment on their mean keypoint distance, relative to the person's size in the image; a
   person lost for a few frames keeps its track.
2. **Agreement between views** (:func:`track_affinity`). Two tracks from two cameras show the same person
   if their viewing rays meet: for each detection of one, the closest approach of corresponding joints'
   rays to some detection of the other within ``window_s`` of it (the unknown clock offsets, and the
   motion in that time, are absorbed by the window), in metres. The median over detections is the
   affinity; different people give the distance between them, the same person a few centimetres.
3. **Subjects** (:func:`associate`). Tracks are merged across cameras by increasing affinity, never two
   tracks of one camera that overlap in time. A subject's support is the number of its detections in
   cameras that agree; the subjects are ranked by it, so a bystander seen by one camera for a few frames
   never takes over, whatever its confidence.

Every array documents its shape; pixels are the detector's (distorted) pixels, undistorted through each
camera's lens before rays are formed; lengths are metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gttdata.cameras import Camera

__all__ = ["CameraPeople", "Subject", "associate", "track_affinity", "track_camera"]


@dataclass(frozen=True)
class CameraPeople:
    """Every person one camera's detector reported.

    Args:
        frame: Frame number of each detection, shape ``(M,)`` int; several detections may share a frame.
        keypoints_px: Joints of each detection, pixels, shape ``(M, J, 2)``, NaN where not found.
        score: Confidence of each joint, shape ``(M, J)``, 0 where not found.
    """

    frame: np.ndarray
    keypoints_px: np.ndarray
    score: np.ndarray

    @property
    def n_detections(self) -> int:
        """M."""
        return int(self.frame.shape[0])


@dataclass(frozen=True)
class Subject:
    """One person found across cameras.

    Args:
        detections: For each camera, the indices into its :class:`CameraPeople` rows that belong to this
            person, in frame order (at most one per frame).
        support: Number of its detections in cameras whose tracks agree with another camera's.
        n_cameras: Number of cameras that see it.
    """

    detections: tuple[np.ndarray, ...]
    support: int
    n_cameras: int


def _size(kp: np.ndarray) -> float:
    """Diagonal of the bounding box of the found joints of one detection ``(J, 2)``, pixels (>= 1)."""
    ok = np.isfinite(kp).all(axis=-1)
    if ok.sum() < 2:
        return 1.0
    return max(float(np.linalg.norm(np.ptp(kp[ok], axis=0))), 1.0)


def _distance(a: np.ndarray, b: np.ndarray) -> float:
    """Median distance of the joints found in both detections ``(J, 2)``, pixels; inf if none is shared."""
    ok = np.isfinite(a).all(axis=-1) & np.isfinite(b).all(axis=-1)
    return float(np.median(np.linalg.norm(a[ok] - b[ok], axis=-1))) if ok.any() else np.inf


def track_camera(people: CameraPeople, *, max_gap: int = 5, gate: float = 0.5) -> np.ndarray:
    """Link one camera's detections into tracks.

    Args:
        people: The camera's detections.
        max_gap: A track waits this many frames for its person before it ends.
        gate: Largest link cost: the median joint distance over the person's size in the image.

    Returns:
        Track id of each detection, shape ``(M,)`` int, numbered from 0 in order of first appearance.

    Example:
        >>> kp = np.array([[[0.0, 0], [10, 10]], [[100, 0], [110, 10]], [[1, 0], [11, 10]], [[101, 1], [111, 11]]])
        >>> track_camera(CameraPeople(np.array([0, 0, 1, 1]), kp, np.ones((4, 2)))).tolist()
        [0, 1, 0, 1]
    """
    from scipy.optimize import linear_sum_assignment

    track = np.full(people.n_detections, -1, dtype=np.int64)
    last: list[tuple[int, int]] = []  # per track: (last detection, last frame)
    for f in np.unique(people.frame):
        rows = np.flatnonzero(people.frame == f)
        alive = [k for k, (_, lf) in enumerate(last) if f - lf <= max_gap]
        if alive:
            cost = np.full((rows.size, len(alive)), np.inf)
            for i, r in enumerate(rows):
                for k, t in enumerate(alive):
                    prev = people.keypoints_px[last[t][0]]
                    cost[i, k] = _distance(people.keypoints_px[r], prev) / _size(prev)
            big = np.where(np.isfinite(cost), cost, 1e9)
            ri, ci = linear_sum_assignment(big)
            for i, k in zip(ri, ci, strict=True):
                if cost[i, k] <= gate:
                    track[rows[i]] = alive[k]
        for r in rows:
            if track[r] < 0:
                track[r] = len(last)
                last.append((int(r), int(f)))
            else:
                last[track[r]] = (int(r), int(f))
    return track


def _rays(kp: np.ndarray, camera: Camera) -> np.ndarray:
    """Unit world rays of pixels ``(..., 2)`` through ``camera``'s lens, shape ``(..., 3)`` (NaN stays NaN)."""
    from gttdata.calibration import undistort_points

    px = undistort_points(kp, camera) if np.any(np.asarray(camera.dist, dtype=np.float64)) else kp
    return camera.pixel_rays(px)[1]


def _ray_gap(c1: np.ndarray, r1: np.ndarray, c2: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Closest approach of ray pairs, metres: centres ``(3,)``, directions ``(..., 3)``; inf behind a camera."""
    w = c1 - c2
    b = np.sum(r1 * r2, axis=-1)
    d, e = r1 @ w, r2 @ w
    den = 1.0 - b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (b * e - d) / den
        t = (e - b * d) / den
    gap = np.linalg.norm(w + s[..., None] * r1 - t[..., None] * r2, axis=-1)
    return np.where((s > 0) & (t > 0) & (den > 1e-9), gap, np.inf)


def track_affinity(
    rays_a: np.ndarray,
    time_a: np.ndarray,
    centre_a: np.ndarray,
    rays_b: np.ndarray,
    time_b: np.ndarray,
    centre_b: np.ndarray,
    *,
    window_s: float,
    max_samples: int = 40,
    min_matches: int = 3,
) -> float:
    """How far apart two tracks from two cameras are, metres (small: the same person).

    Args:
        rays_a: World rays of track a's joints, shape ``(Ma, J, 3)``, NaN where not found.
        time_a: Nominal time of each of a's detections on its camera's clock, seconds, shape ``(Ma,)``.
        centre_a: Camera a's centre, world metres, shape ``(3,)``.
        rays_b: As ``rays_a``, for track b, shape ``(Mb, J, 3)``.
        time_b: As ``time_a``, shape ``(Mb,)``.
        centre_b: Camera b's centre, shape ``(3,)``.
        window_s: Largest clock offset (plus motion) between the cameras, seconds.
        max_samples: At most this many detections of a are compared (evenly spaced).
        min_matches: Fewer detections of a with a match than this is no evidence (inf): a track of one
            or two detections agrees with anything by chance.

    Returns:
        Median over a's sampled detections of the smallest mean ray gap to any detection of b within
        ``window_s``; inf when no detection of b is that close in time.
    """
    if rays_a.shape[0] == 0 or rays_b.shape[0] == 0:
        return np.inf
    pick = np.unique(
        np.linspace(0, rays_a.shape[0] - 1, min(max_samples, rays_a.shape[0])).round().astype(int)
    )
    best = []
    for i in pick:
        near = np.flatnonzero(np.abs(time_b - time_a[i]) <= window_s)
        if near.size == 0:
            continue
        gap = _ray_gap(centre_a, rays_a[i][None], centre_b, rays_b[near])  # (n, J)
        ok = np.isfinite(gap)
        counts = ok.sum(axis=1)
        mean = np.where(counts >= 3, np.where(ok, gap, 0.0).sum(axis=1) / np.maximum(counts, 1), np.inf)
        best.append(float(mean.min()))
    finite = [b for b in best if np.isfinite(b)]
    return float(np.median(finite)) if len(finite) >= min_matches else np.inf


def _camera_tracks(
    people: Sequence[CameraPeople], cameras: Sequence[Camera], fps: Sequence[float], min_score: float
) -> list[tuple[int, np.ndarray, np.ndarray, np.ndarray]]:
    """Every camera's tracks: ``(camera, rows in frame order, rays (M, J, 3), nominal times (M,))``."""
    out = []
    for v, p in enumerate(people):
        kp = np.where((p.score >= min_score)[..., None], p.keypoints_px, np.nan)
        ids = track_camera(CameraPeople(p.frame, kp, p.score))
        for t in np.unique(ids):
            rows = np.flatnonzero(ids == t)
            rows = rows[np.argsort(p.frame[rows], kind="stable")]
            out.append((v, rows, _rays(kp[rows], cameras[v]), p.frame[rows] / float(fps[v])))
    return out


def _merge(
    tracks: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]],
    people: Sequence[CameraPeople],
    pairs: list[tuple[float, int, int]],
) -> list[list[int]]:
    """Clusters of tracks, merged by increasing gap, never two tracks of one camera sharing a frame."""
    cluster = list(range(len(tracks)))
    members: dict[int, list[int]] = {k: [k] for k in range(len(tracks))}

    def overlaps(x: int, y: int) -> bool:
        vx, vy = tracks[x][0], tracks[y][0]
        if vx != vy:
            return False
        return bool(np.intersect1d(people[vx].frame[tracks[x][1]], people[vy].frame[tracks[y][1]]).size)

    for _, a, b in sorted(pairs):
        ca, cb = cluster[a], cluster[b]
        if ca == cb or any(overlaps(x, y) for x in members[ca] for y in members[cb]):
            continue
        for m in members[cb]:
            cluster[m] = ca
        members[ca].extend(members.pop(cb))
    return list(members.values())


def associate(
    people: Sequence[CameraPeople],
    cameras: Sequence[Camera],
    fps: Sequence[float],
    *,
    n_subjects: int = 1,
    window_s: float = 1.0,
    max_gap_m: float = 0.25,
    min_score: float = 0.1,
) -> list[Subject]:
    """Find the ``n_subjects`` best-supported people across unsynchronized cameras.

    Args:
        people: Each camera's detections.
        cameras: The calibrated cameras, in the same order.
        fps: Each camera's nominal frame rate, Hz (for the time window only; clocks may be offset).
        n_subjects: How many people to return, most supported first.
        window_s: Largest clock offset between cameras (plus motion in that time), seconds.
        max_gap_m: Two tracks farther apart than this (:func:`track_affinity`) are different people.
        min_score: Joints scored below this are ignored.

    Returns:
        Up to ``n_subjects`` subjects, by decreasing support; each has at most one detection per frame of
        each camera.

    Raises:
        ValueError: ``people``, ``cameras`` and ``fps`` differ in length.
    """
    V = len(people)
    if not (len(cameras) == len(fps) == V):
        raise ValueError(f"associate: {V} cameras of detections, {len(cameras)} cameras, {len(fps)} rates")
    tracks = _camera_tracks(people, cameras, fps, min_score)
    centre = [np.asarray(cameras[v].center, dtype=np.float64) for v, *_ in tracks]
    pairs = []
    for a in range(len(tracks)):
        for b in range(a + 1, len(tracks)):
            if tracks[a][0] == tracks[b][0]:
                continue
            (_, _, ra, ta), (_, _, rb, tb) = tracks[a], tracks[b]
            g = max(
                track_affinity(ra, ta, centre[a], rb, tb, centre[b], window_s=window_s),
                track_affinity(rb, tb, centre[b], ra, ta, centre[a], window_s=window_s),
            )
            if g <= max_gap_m:
                pairs.append((g, a, b))
    subjects = []
    for ms in _merge(tracks, people, pairs):
        cams = {tracks[m][0] for m in ms}
        if len(cams) < 2:
            continue  # seen by one camera only: nothing agrees with it
        per_cam = []
        for v in range(V):
            rows = [tracks[m][1] for m in ms if tracks[m][0] == v]
            r = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
            per_cam.append(r[np.argsort(people[v].frame[r], kind="stable")])
        support = int(sum(r.size for r in per_cam))
        subjects.append(Subject(detections=tuple(per_cam), support=support, n_cameras=len(cams)))
    subjects.sort(key=lambda s: -s.support)
    return subjects[:n_subjects]
