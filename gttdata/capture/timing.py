"""Per-camera clocks (rate, offset, drift, jitter) that give every image its capture time."""

from __future__ import annotations

import logging

import numpy as np

__all__ = [
    "STAGGER_MODES",
    "camera_offsets",
    "min_cross_camera_gap",
    "sample_timestamps",
    "separate_timestamps",
]

_log = logging.getLogger(__name__)

#: ``even``: camera slot ``v`` starts at ``v / (V * fps_max)`` (slots shuffled across cameras);
#: ``random``: each camera starts uniformly within its own period.
STAGGER_MODES: tuple[str, ...] = ("even", "random")


def camera_offsets(fps_hz: np.ndarray, *, stagger: str = "even", rng: np.random.Generator) -> np.ndarray:
    """Start time of each camera's first image.

    With ``even`` and rates that divide the fastest one by powers of two (e.g. 7.5 / 15 / 30 Hz), every
    image lies on its camera's own residue of the ``1 / (V fps_max)`` grid, so no two cameras ever
    coincide; :func:`separate_timestamps` enforces the guarantee for any other mix.

    Args:
        fps_hz: Frame rate per camera, Hz, shape ``(V,)``.
        stagger: One of :data:`STAGGER_MODES`.
        rng: Random generator (slot shuffle or offsets).

    Returns:
        Offsets in seconds, shape ``(V,)``, each in ``[0, 1 / fps_v)``.
    """
    fps = np.asarray(fps_hz, dtype=np.float64)
    v = fps.shape[0]
    if stagger == "even":
        slots = rng.permutation(v)
        return slots / (v * fps.max())
    if stagger == "random":
        return rng.uniform(0.0, 1.0, size=v) / fps
    raise ValueError(f"stagger must be one of {STAGGER_MODES}, got {stagger!r}")


def min_cross_camera_gap(timestamp_s: np.ndarray, cam_id: np.ndarray) -> float:
    """Smallest ``|t_i - t_j|`` over image pairs of different cameras, seconds (inf if one camera).

    Args:
        timestamp_s: Image times, seconds, shape ``(N,)``.
        cam_id: Camera of each image, shape ``(N,)``.
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    c = np.asarray(cam_id)
    order = np.argsort(t, kind="stable")
    t, c = t[order], c[order]
    best = np.inf
    # The closest other-camera image of any image is its nearest other-camera neighbour in sorted order.
    for v in np.unique(c):
        mine = c == v
        if mine.all():
            continue
        other_t = t[~mine]
        pos = np.searchsorted(other_t, t[mine])
        lo = np.abs(t[mine] - other_t[np.clip(pos - 1, 0, other_t.size - 1)])
        hi = np.abs(other_t[np.clip(pos, 0, other_t.size - 1)] - t[mine])
        best = min(best, float(np.minimum(lo, hi).min()))
    return best


def separate_timestamps(timestamp_s: np.ndarray, *, min_gap_s: float) -> np.ndarray:
    """Push images later, in time order, until consecutive images are at least ``min_gap_s`` apart.

    Only images closer than ``min_gap_s`` to their predecessor move, each by less than
    ``N * min_gap_s``; the time order (hence every stream's order) is unchanged.

    Args:
        timestamp_s: Image times, seconds, shape ``(N,)``.
        min_gap_s: Required gap, seconds.

    Returns:
        New times, shape ``(N,)``, with ``min |t_i - t_j| >= min_gap_s`` over all pairs.
    """
    t = np.asarray(timestamp_s, dtype=np.float64).copy()
    order = np.argsort(t, kind="stable")
    ts = t[order]
    moved = 0
    for k in range(1, ts.size):
        if ts[k] - ts[k - 1] < min_gap_s:
            ts[k] = ts[k - 1] + min_gap_s
            moved += 1
    if moved:
        _log.debug("separated %d near-concurrent images (min gap %.3g s)", moved, min_gap_s)
    t[order] = ts
    return t


def sample_timestamps(
    fps_hz: np.ndarray,
    duration_s: float,
    *,
    offsets_s: np.ndarray,
    rng: np.random.Generator,
    jitter_s: float = 0.0,
    drift_ppm: np.ndarray | float = 0.0,
    min_gap_s: float = 1e-4,
    frame_counter: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Capture times of every image of every camera within ``[0, duration_s)``.

    Camera ``v`` takes frame ``k = 0, 1, ...`` at ``offset_v + k (1 + drift_v 1e-6) / fps_v + e`` (a negative
    offset: the camera started before the capture, and its frames before time 0 are not kept), with timing jitter
    ``e ~ N(0, jitter_s)`` clipped to a quarter of the camera's period (so a stream never reorders),
    then :func:`separate_timestamps` guarantees no two images are concurrent.

    Args:
        fps_hz: Nominal frame rate per camera, Hz, shape ``(V,)``.
        duration_s: Capture duration, seconds.
        offsets_s: Clock offset per camera, seconds, shape ``(V,)`` (see :func:`camera_offsets`).
        rng: Random generator for the jitter.
        jitter_s: Std of the per-image jitter, seconds.
        drift_ppm: Clock rate error per camera (or one for all), parts per million.
        min_gap_s: Smallest gap between any two images, seconds.
        frame_counter: Return each image's ``k`` (its camera's frame counter since the camera started)
            instead of its index among the kept images of its camera.

    Returns:
        ``(cam_id, timestamp_s, stream_index)`` sorted by time: shapes ``(N,)`` int32, float64, int32.
    """
    fps = np.asarray(fps_hz, dtype=np.float64)
    drift = np.broadcast_to(np.asarray(drift_ppm, dtype=np.float64), fps.shape)
    offs = np.asarray(offsets_s, dtype=np.float64)
    cams, times, idx = [], [], []
    for v in range(fps.shape[0]):
        period = (1.0 + drift[v] * 1e-6) / fps[v]
        k = np.arange(int(np.ceil(max(duration_s - offs[v], 0.0) / period)) + 1)
        t = offs[v] + k * period
        if jitter_s > 0:
            t = t + np.clip(rng.normal(0.0, jitter_s, size=t.shape), -period / 4, period / 4)
        keep = (t >= 0.0) & (t < duration_s)
        t = t[keep]
        cams.append(np.full(t.shape, v, dtype=np.int32))
        times.append(t)
        idx.append(k[keep].astype(np.int32) if frame_counter else np.arange(t.shape[0], dtype=np.int32))
    cam = np.concatenate(cams)
    t = separate_timestamps(np.concatenate(times), min_gap_s=min_gap_s)
    si = np.concatenate(idx)
    order = np.argsort(t, kind="stable")
    return cam[order], t[order], si[order]
