"""Dance tracks: rhythmic whole-body patterns on a musical beat, several per motion, cross-faded."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from gttdata.mocap.procedural._actions import stand_base, twist_pelvis
from gttdata.mocap.procedural._body import Body
from gttdata.mocap.procedural._track import Track, segment_weights

__all__ = ["DANCE_PATTERNS", "dance_track"]


def _bounce(track: Track, knee: np.ndarray) -> None:
    """Knee bend with the thighs taking half of it and the feet kept flat on the floor."""
    track.add_sides("femur", 1, 0.5 * knee, 0.5 * knee)
    track.add_sides("tibia", 1, knee, knee)
    track.add_sides("foot", 1, 0.5 * knee, 0.5 * knee)


def _sway(track: Track, angle: np.ndarray) -> None:
    """Sideways weight shift: both legs rotate by the same frontal angle, ankles counter-rotate."""
    track.add_sides("femur", 0, angle, -angle)
    track.add_sides("foot", 0, -angle, angle)


def _tap(track: Track, side: str, lift: np.ndarray) -> None:
    """Lift the unloaded foot off the floor (``lift`` in [0, 1])."""
    track.add(side + "femur", 1, 20.0 * lift)
    track.add(side + "tibia", 1, 35.0 * lift)
    track.add(side + "foot", 1, -10.0 * lift)


def _pattern_bounce(track: Track, u: np.ndarray, rng: np.random.Generator) -> None:
    _bounce(track, 8.0 + rng.uniform(8.0, 16.0) * 0.5 * (1.0 + np.cos(u)))
    pump = np.cos(0.5 * u)
    track.add_sides("humerus", 1, 35.0 + 30.0 * pump, 35.0 - 30.0 * pump)
    track.add_sides("radius", 1, 95.0 - 30.0 * pump, 95.0 + 30.0 * pump)
    track.add_sides("humerus", 0, 15.0, 15.0)
    track.add("upperneck", 1, 6.0 * np.cos(u))
    track.add("thorax", 2, 8.0 * np.sin(0.5 * u))


def _pattern_step_touch(track: Track, u: np.ndarray, rng: np.random.Generator) -> None:
    s = np.sin(0.5 * u)
    _sway(track, rng.uniform(6.0, 10.0) * s)
    _bounce(track, 6.0 + 8.0 * 0.5 * (1.0 + np.cos(u)))
    _tap(track, "l", np.maximum(s, 0.0) ** 2)
    _tap(track, "r", np.maximum(-s, 0.0) ** 2)
    track.add_sides("humerus", 0, 20.0 + 15.0 * s, 20.0 - 15.0 * s)
    track.add_sides("radius", 1, 50.0, 50.0)
    track.add("lowerback", 0, -5.0 * s)


def _pattern_twist(track: Track, u: np.ndarray, rng: np.random.Generator) -> None:
    phi = rng.uniform(15.0, 30.0) * np.sin(u)
    twist_pelvis(track, phi)
    for j in ("lowerback", "upperback", "thorax"):
        track.add(j, 2, -phi / 3.0)
    _bounce(track, 20.0 + 6.0 * np.cos(2.0 * u))
    track.add_sides("humerus", 0, 60.0, 60.0)
    track.add_sides("radius", 1, 90.0, 90.0)
    track.add_sides("humerus", 1, 20.0 - 0.5 * phi, 20.0 + 0.5 * phi)


def _pattern_disco(track: Track, u: np.ndarray, rng: np.random.Generator) -> None:
    side, other = ("l", "r") if rng.uniform() < 0.5 else ("r", "l")
    w = 0.5 * (1.0 + np.sin(0.5 * u))
    track.add(side + "humerus", 1, 20.0 + 130.0 * w)
    track.add(side + "humerus", 0, -15.0 + 55.0 * w)
    track.add(side + "radius", 1, 10.0)
    track.add(other + "humerus", 0, 45.0)
    track.add(other + "humerus", 2, 40.0)
    track.add(other + "radius", 1, 110.0)
    _sway(track, 6.0 * np.sin(0.5 * u))
    _bounce(track, 6.0 + 6.0 * 0.5 * (1.0 + np.cos(u)))
    track.add("upperneck", 1, -15.0 * w * (1.0 if side == "l" else 1.0))
    track.add("upperneck", 2, (20.0 if side == "l" else -20.0) * w)


def _pattern_spin(track: Track, u: np.ndarray, rng: np.random.Generator) -> None:
    # Turning needs steps: lift the feet alternately on the beat (the ground stage pivots the body
    # about whichever foot is down).
    s = np.sin(0.5 * u)
    _tap(track, "l", np.maximum(s, 0.0) ** 2)
    _tap(track, "r", np.maximum(-s, 0.0) ** 2)
    _bounce(track, 10.0 + 6.0 * 0.5 * (1.0 + np.cos(u)))
    track.add_sides("humerus", 0, 75.0, 75.0)
    track.add_sides("radius", 1, 25.0, 25.0)
    track.add("upperneck", 1, 5.0 * np.cos(u))


def _pattern_arms_wave(track: Track, u: np.ndarray, rng: np.random.Generator) -> None:
    s = np.sin(0.5 * u)
    track.add_sides("humerus", 0, 100.0 + 20.0 * np.cos(u), 100.0 + 20.0 * np.cos(u))
    track.add_sides("radius", 1, 80.0 + 20.0 * s, 80.0 - 20.0 * s)
    track.add_sides("humerus", 2, -80.0, -80.0)
    track.add("lowerback", 0, 8.0 * s)
    track.add("upperback", 0, 4.0 * s)
    _sway(track, 5.0 * s)
    _bounce(track, 8.0 + 6.0 * 0.5 * (1.0 + np.cos(u)))


#: Dance patterns by name: ``pattern(track, beat_angle_rad, rng)`` adds angles for the whole track.
DANCE_PATTERNS: dict[str, Callable[[Track, np.ndarray, np.random.Generator], None]] = {
    "bounce": _pattern_bounce,
    "step_touch": _pattern_step_touch,
    "twist": _pattern_twist,
    "disco": _pattern_disco,
    "spin": _pattern_spin,
    "arms_wave": _pattern_arms_wave,
}


def dance_track(
    rng: np.random.Generator,
    kind: str,
    n_frames: int,
    fps_hz: float,
    body: Body,
    *,
    speed_scale: float | None,
) -> tuple[Track, dict]:
    """Dance: 2-4 rhythmic patterns of 8-16 beats each at 85-135 BPM, cross-faded over 1.5 beats.

    Args:
        rng: Random generator.
        kind: ``"dance"``.
        n_frames: Number of frames T.
        fps_hz: Frame rate, Hz.
        body: The subject.
        speed_scale: Tempo as a multiple of 110 BPM; drawn when None.

    Returns:
        ``(track, params)``: the track, the tempo and the pattern sequence.
    """
    bpm = 110.0 * speed_scale if speed_scale is not None else rng.uniform(85.0, 135.0)
    track = Track.zeros(n_frames, fps_hz)
    t = track.times_s
    beat_s = 60.0 / bpm
    u = 2.0 * np.pi * (t / beat_s + rng.uniform(0.0, 1.0))
    names = list(DANCE_PATTERNS)
    seq: list[str] = []
    bounds = [0.0]
    while bounds[-1] < t[-1]:
        choices = [n for n in names if not seq or n != seq[-1]]
        seq.append(str(rng.choice(choices)))
        bounds.append(bounds[-1] + beat_s * int(rng.choice((8, 12, 16))))
    bounds[-1] = max(bounds[-1], t[-1] + 1.0)
    weights = segment_weights(t, bounds, 1.5 * beat_s)
    for k, name in enumerate(seq):
        part = Track.zeros(n_frames, fps_hz)
        DANCE_PATTERNS[name](part, u, rng)
        track.angles += weights[:, k, None, None] * part.angles
        if name == "spin":
            turns = rng.choice((-1.0, 1.0)) * 2.0 * np.pi / (8.0 * beat_s)
            # Turn only while one foot is lifted (sin^2 of the step phase, mean 1/2), not in double support.
            track.yaw_rate += weights[:, k] * turns * 2.0 * np.sin(0.5 * u) ** 2
    stand_base(rng, track, calm=0.3)
    return track, {"bpm": float(bpm), "patterns": seq}
