"""Mixed tracks: segments of several kinds, cross-faded smoothly in joint-angle space."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gttdata.mocap.procedural._body import Body
from gttdata.mocap.procedural._track import Track, segment_weights

__all__ = ["mixed_track"]

# Seconds over which one segment fades into the next; blending angles, yaw rates and support before
# the root path is derived keeps positions and velocities continuous across the seams.
_FADE_S = 1.0


def mixed_track(
    rng: np.random.Generator,
    kinds: tuple[str, ...],
    n_frames: int,
    fps_hz: float,
    body: Body,
    *,
    speed_scale: float | None,
    build: Callable[..., tuple[Track, dict]],
) -> tuple[Track, dict]:
    """Concatenate 2-4 segments (at least 2.5 s each) of different kinds with 1 s cross-fades.

    Args:
        rng: Random generator.
        kinds: Kinds to draw segments from.
        n_frames: Number of frames T.
        fps_hz: Frame rate, Hz.
        body: The subject.
        speed_scale: Passed to every segment's generator.
        build: ``build(rng, kind, n_frames, fps_hz, body, speed_scale)`` makes one segment's track.

    Returns:
        ``(track, params)``: the blended track and the segments (kind, start, end, parameters).
    """
    duration = (n_frames - 1) / fps_hz
    n_seg = int(np.clip(rng.integers(2, 5), 1, max(1, int(duration // 2.5))))
    cuts = np.sort(rng.uniform(0.0, 1.0, n_seg - 1))
    # Spread the cuts so that every segment lasts at least 2.5 s when the duration allows it.
    min_len = min(2.5, duration / n_seg)
    bounds = [
        0.0,
        *(min_len * (i + 1) + c * (duration - n_seg * min_len) for i, c in enumerate(cuts)),
        duration,
    ]
    t = np.arange(n_frames) / fps_hz
    weights = segment_weights(t, [*bounds[:-1], duration + 1.0], _FADE_S)
    track = Track.zeros(n_frames, fps_hz)
    track.support[:] = 0.0
    segments, previous = [], None
    for k in range(n_seg):
        kind = str(rng.choice([x for x in kinds if x != previous]))
        previous = kind
        lo = max(0, int(np.floor((bounds[k] - _FADE_S) * fps_hz)))
        hi = min(n_frames, int(np.ceil((bounds[k + 1] + _FADE_S) * fps_hz)) + 1)
        part, params = build(rng, kind, hi - lo, fps_hz, body, speed_scale)
        w = weights[lo:hi, k]
        track.angles[lo:hi] += w[:, None, None] * part.angles
        track.yaw_rate[lo:hi] += w * part.yaw_rate
        track.support[lo:hi] += w * part.support
        track.flight_vel[lo:hi] += w[:, None] * part.flight_vel
        track.contact[lo:hi] += w[:, None] * part.contact
        track.contact_mix[lo:hi] += w * part.contact_mix
        segments.append(
            {"kind": kind, "start_s": round(bounds[k], 3), "end_s": round(bounds[k + 1], 3), **params}
        )
    return track, {"segments": segments}
