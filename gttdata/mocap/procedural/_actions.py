"""Standing tracks: idling with weight shifts, and arm gestures (waving, reaching, pointing)."""

from __future__ import annotations

import numpy as np

from gttdata.mocap.procedural._body import Body
from gttdata.mocap.procedural._jump import jump_track
from gttdata.mocap.procedural._track import Track, smooth_noise, smootherstep

__all__ = ["action_track", "stand_base", "twist_pelvis"]

# Arm targets per gesture, anatomical degrees: (shoulder abduction, shoulder flexion, shoulder
# internal rotation, elbow flexion, wrist flexion), each a (low, high) range; plus the head turn
# towards the gesturing side and the thorax twist, degrees.
_GESTURES: dict[str, dict] = {
    "wave": {
        # External rotation turns the flexed forearm up into the frontal plane.
        "arm": ((85, 130), (5, 35), (-100, -70), (60, 100), (-10, 10)),
        "head": 15,
        "twist": 5,
        "osc": True,
    },
    "reach_front": {"arm": ((0, 25), (70, 110), (0, 20), (0, 20), (-10, 20)), "head": 5, "twist": 12},
    "reach_up": {"arm": ((10, 40), (140, 170), (-10, 10), (0, 25), (0, 20)), "head": -10, "twist": 5},
    "reach_side": {"arm": ((70, 95), (0, 30), (-10, 10), (0, 20), (-10, 10)), "head": 25, "twist": -10},
    "point": {"arm": ((10, 60), (65, 95), (-10, 10), (0, 12), (0, 10)), "head": 30, "twist": 15},
    "beckon": {
        "arm": ((5, 30), (40, 70), (20, 40), (70, 110), (-20, 20)),
        "head": 10,
        "twist": 5,
        "osc": True,
    },
    "hands_on_hips": {"arm": ((35, 50), (-15, 0), (30, 45), (95, 120), (0, 20)), "head": 0, "twist": 0},
    "hand_to_face": {"arm": ((5, 25), (40, 70), (40, 60), (120, 140), (10, 40)), "head": -5, "twist": 5},
    "arms_crossed": {"arm": ((10, 25), (20, 40), (60, 80), (95, 120), (0, 10)), "head": 0, "twist": 0},
}
_GESTURE_KINDS = ("wave", "reach_front", "reach_up", "reach_side", "point", "beckon")
_IDLE_KINDS = ("hands_on_hips", "hand_to_face", "arms_crossed", "reach_front", "point")


def _smooth_abs(x: np.ndarray) -> np.ndarray:
    """|x| rounded off near 0, so that noise folded to positive values keeps a continuous slope."""
    return np.sqrt(x * x + 0.04)


def twist_pelvis(track: Track, phi: np.ndarray) -> None:
    """Twist the pelvis by ``phi`` degrees (to the left) with both feet staying where they are.

    The thighs counter-rotate about their axes so the feet keep pointing forward, and each leg
    tilts forward or back by the angle that cancels its hip joint's fore-aft displacement (the
    hip joints sit ~0.08 m either side of the root, ~0.9 m above the ankles); the ankles keep the
    feet flat.
    """
    track.add("root", 2, phi)
    track.add_sides("femur", 2, phi, -phi)
    tilt = np.rad2deg(np.arcsin(0.085 * np.sin(np.deg2rad(phi))))
    track.add_sides("femur", 1, tilt, -tilt)
    track.add_sides("foot", 1, -tilt, tilt)


def stand_base(rng: np.random.Generator, track: Track, *, calm: float = 1.0) -> None:
    """Add a relaxed standing posture with weight shifts, breathing, head movement and arm drift.

    The weight shift rotates both legs by the same frontal angle and counter-rotates the ankles
    (a parallelogram), so both feet stay flat on the floor while the pelvis moves sideways.

    Args:
        rng: Random generator.
        track: Track to add to.
        calm: Amplitude factor of the random movement (1 = ordinary idling).
    """
    t = track.times_s
    n = smooth_noise(rng, t, 14, max_hz=0.5)
    width = rng.uniform(2.0, 7.0)
    shift = calm * rng.uniform(2.0, 4.0) * smooth_noise(rng, t, 1, max_hz=0.25)[:, 0]
    track.add_sides("femur", 0, width + shift, width - shift)
    track.add_sides("foot", 0, -width - shift, -width + shift)
    toe_out = rng.uniform(0.0, 15.0)
    track.add_sides("femur", 2, -toe_out, -toe_out)
    knee = rng.uniform(2.0, 8.0) + calm * 2.0 * _smooth_abs(n[:, :2])
    # Hip flexion compensates the pelvis tilt so thighs and feet keep their world orientation.
    tilt = rng.uniform(0.0, 5.0)
    track.add("root", 1, tilt)
    track.add_sides("femur", 1, tilt + 0.5 * knee[:, 0], tilt + 0.5 * knee[:, 1])
    track.add_sides("tibia", 1, knee[:, 0], knee[:, 1])
    track.add_sides("foot", 1, 0.5 * knee[:, 0], 0.5 * knee[:, 1])
    breath = 1.5 * np.sin(2.0 * np.pi * rng.uniform(0.2, 0.3) * t + rng.uniform(0, 2 * np.pi))
    track.add("upperback", 1, rng.uniform(-2.0, 4.0) + 2.0 * calm * n[:, 2] - breath)
    track.add("thorax", 1, breath + calm * n[:, 3])
    track.add("lowerback", 0, calm * 2.0 * n[:, 4] - 0.3 * shift)
    track.add("thorax", 2, calm * 4.0 * n[:, 5])
    twist_pelvis(track, calm * 6.0 * smooth_noise(rng, t, 1, max_hz=0.15)[:, 0])
    track.add("upperneck", 2, calm * 20.0 * n[:, 6])
    track.add("upperneck", 1, calm * 8.0 * n[:, 7])
    track.add("head", 0, calm * 5.0 * n[:, 8])
    abd = rng.uniform(4.0, 12.0)
    track.add_sides("humerus", 0, abd + 3.0 * calm * n[:, 9], abd + 3.0 * calm * n[:, 10])
    track.add_sides("humerus", 1, 4.0 * calm * n[:, 11], 4.0 * calm * n[:, 12])
    elbow = rng.uniform(8.0, 25.0)
    track.add_sides(
        "radius", 1, elbow + 5.0 * calm * _smooth_abs(n[:, 13]), elbow + 5.0 * calm * _smooth_abs(n[:, 0])
    )
    track.add_sides("humerus", 2, rng.uniform(5.0, 20.0), rng.uniform(5.0, 20.0))


def _envelope(t: np.ndarray, start: float, rise: float, hold: float, fall: float) -> np.ndarray:
    """Smooth 0 -> 1 -> 0 window: C2 ramps of ``rise`` and ``fall`` seconds around a ``hold``."""
    return smootherstep((t - start) / rise) * (1.0 - smootherstep((t - start - rise - hold) / fall))


def _gesture(
    rng: np.random.Generator, track: Track, name: str, side: str, env: np.ndarray, tempo: float
) -> None:
    """Add one gesture of one arm, weighted by the envelope ``env`` (shape ``(T,)``)."""
    spec = _GESTURES[name]
    abd, flex, rot, elbow, wrist = (rng.uniform(lo, hi) for lo, hi in spec["arm"])
    sgn = 1.0 if side == "l" else -1.0
    if spec.get("osc"):
        f = rng.uniform(1.2, 2.2) * tempo
        osc = np.sin(2.0 * np.pi * f * track.times_s + rng.uniform(0, 2 * np.pi))
        rot = rot + 18.0 * osc
        elbow = elbow + 12.0 * osc
    # Relative to the relaxed base pose, which already holds ~8 deg abduction and ~15 deg elbow flexion.
    track.add(side + "humerus", 0, env * (abd - 8.0))
    track.add(side + "humerus", 1, env * flex)
    track.add(side + "humerus", 2, env * rot)
    track.add(side + "radius", 1, env * (elbow - 15.0))
    track.add(side + "wrist", 1, env * wrist)
    track.add("upperneck", 2, env * sgn * spec["head"])
    track.add("thorax", 2, env * sgn * spec["twist"])
    if name.startswith("reach"):
        track.add("upperback", 1, env * rng.uniform(0.0, 12.0))


def _gesture_sequence(
    rng: np.random.Generator, track: Track, names: tuple[str, ...], *, tempo: float, pace: float
) -> list[str]:
    """Schedule gestures one after another over the track; returns their names."""
    t = track.times_s
    start, done = rng.uniform(0.2, 1.0), []
    while start < t[-1] - 1.0:
        name = str(rng.choice(names))
        rise, fall = rng.uniform(0.6, 1.0) / tempo, rng.uniform(0.6, 1.1) / tempo
        hold = rng.uniform(0.6, 2.5) * pace
        env = _envelope(t, start, rise, hold, fall)
        both = name in ("hands_on_hips", "arms_crossed", "reach_up") and rng.uniform() < 0.6
        sides = ("l", "r") if both else (str(rng.choice(("l", "r"))),)
        for side in sides:
            _gesture(rng, track, name, side, env, tempo)
        done.append(name if not both else name + "/both")
        start += rise + hold + fall + rng.uniform(0.1, 1.2) * pace
    return done


def action_track(
    rng: np.random.Generator,
    kind: str,
    n_frames: int,
    fps_hz: float,
    body: Body,
    *,
    speed_scale: float | None,
) -> tuple[Track, dict]:
    """Standing track for ``kind`` in ("idle", "gesture", "jump").

    Args:
        rng: Random generator.
        kind: Action kind.
        n_frames: Number of frames T.
        fps_hz: Frame rate, Hz.
        body: The subject.
        speed_scale: Tempo of the gestures as a multiple of the nominal; drawn when None.

    Returns:
        ``(track, params)``: the track and the parameters drawn.
    """
    if kind == "jump":
        return jump_track(rng, n_frames, fps_hz, body, speed_scale=speed_scale)
    tempo = speed_scale if speed_scale is not None else rng.uniform(0.8, 1.25)
    track = Track.zeros(n_frames, fps_hz)
    calm = 1.0 if kind == "idle" else 0.6
    stand_base(rng, track, calm=calm)
    if kind == "idle":
        names = (
            _gesture_sequence(rng, track, _IDLE_KINDS, tempo=0.7 * tempo, pace=2.0)
            if rng.uniform() < 0.6
            else []
        )
    else:
        names = _gesture_sequence(rng, track, _GESTURE_KINDS, tempo=tempo, pace=1.0)
    return track, {"tempo": float(tempo), "gestures": names}
