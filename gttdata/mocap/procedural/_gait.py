"""Locomotion tracks (walk, jog, run, curved-path and in-place turning) from periodic gait cycles."""

from __future__ import annotations

import numpy as np
from scipy.interpolate import CubicSpline

from gttdata.mocap.procedural._body import JOINT, Body
from gttdata.mocap.procedural._ground import GAIT_AVERAGING_S
from gttdata.mocap.procedural._plant import plant_stance_feet
from gttdata.mocap.procedural._track import Track, smooth_noise, smootherstep

__all__ = ["GAIT_SPEEDS_MPS", "gait_track"]

#: Nominal speed range of each locomotion kind, m/s.
GAIT_SPEEDS_MPS: dict[str, tuple[float, float]] = {
    "walk": (0.8, 1.3),
    "turn": (0.7, 1.25),
    "jog": (1.9, 2.7),
    "run": (2.8, 3.5),
}


def _periodic(keys: list[tuple[float, float]]) -> CubicSpline:
    """Periodic C2 spline through (percent of gait cycle, degrees) keys, evaluated on cycle fraction."""
    k = np.asarray(keys, dtype=np.float64)
    x = np.append(k[:, 0] / 100.0, 1.0 + k[0, 0] / 100.0)
    y = np.append(k[:, 1], k[0, 1])
    return CubicSpline(x, y, bc_type="periodic")


# Sagittal joint angles over one stride, left heel strike at 0 %, degrees (after Winter's normative
# gait data for walking and Novacheck's for running). Walk: toe-off at ~62 %; run: toe-off at ~38 %.
_WALK = {
    "hip": _periodic([(0, 28), (12, 24), (35, 4), (53, -11), (65, 2), (85, 31), (95, 30)]),
    "knee": _periodic([(0, 4), (15, 17), (40, 5), (60, 36), (72, 58), (89, 25)]),
    "ankle": _periodic([(0, 0), (8, -6), (25, 4), (45, 10), (56, 0), (63, -16), (75, -4), (88, 2)]),
}
_RUN = {
    "hip": _periodic([(0, 36), (18, 16), (38, -10), (55, 8), (80, 52), (93, 42)]),
    "knee": _periodic([(0, 20), (13, 42), (37, 18), (66, 105), (85, 55), (95, 25)]),
    "ankle": _periodic([(0, 4), (15, 20), (38, -24), (55, -6), (80, 8)]),
}
_STANCE_FRACTION = {"walk": 0.62, "run": 0.38}
# Style variants per kind and their odds: walking backwards, crouched (sneaking), carrying something
# in one hand (that arm does not swing), uneven (one leg takes shorter strides, as when limping).
_VARIANTS: dict[str, tuple[tuple[str, ...], tuple[float, ...]]] = {
    "walk": (("normal", "backward", "crouched", "carrying", "uneven"), (0.6, 0.1, 0.1, 0.1, 0.1)),
    "turn": (("normal", "crouched", "carrying"), (0.8, 0.1, 0.1)),
    "jog": (("normal", "carrying", "uneven"), (0.8, 0.1, 0.1)),
    "run": (("normal",), (1.0,)),
}


def _phase(
    rng: np.random.Generator, track: Track, speed: np.ndarray, mode: str, leg_m: float, *, backward: bool
) -> np.ndarray:
    """Left-leg gait phase in cycles (unwrapped), from a cadence that grows with speed.

    Walking backwards runs the cycle in reverse: the stance foot then sweeps forward under the body.
    """
    if mode == "walk":
        freq = (0.45 + 0.33 * speed) * np.sqrt(0.91 / leg_m)
    else:
        freq = (1.2 + 0.1 * speed) * np.sqrt(0.91 / leg_m)
    sign = -1.0 if backward else 1.0
    return rng.uniform(0.0, 1.0) + sign * np.concatenate(([0.0], np.cumsum(freq[:-1]) / track.fps_hz))


def _legs(track: Track, s_left: np.ndarray, mode: str, amp: np.ndarray, style: dict) -> None:
    """Hip, knee and ankle angles of both legs, plus stance-side hip adduction."""
    curves = _WALK if mode == "walk" else _RUN
    crouch = style["crouch"]
    for side, s, gain in (
        ("l", s_left % 1.0, style["leg_gain"][0]),
        ("r", (s_left + 0.5) % 1.0, style["leg_gain"][1]),
    ):
        hip, knee, ankle = (curves[k](s) for k in ("hip", "knee", "ankle"))
        a = amp * gain
        # Scale about the mean flexion so slow gaits use a smaller range of motion; a crouched gait
        # adds knee and hip flexion with the ankle keeping the foot's orientation.
        track.add(side + "femur", 1, 10.0 + a * (hip - 10.0) + 20.0 * crouch)
        track.add(side + "tibia", 1, a * knee + (1.0 - a) * style["knee_bend"] + 28.0 * crouch)
        track.add(side + "foot", 1, a * ankle + 8.0 * crouch)
        stance = np.sin(np.pi * np.clip(s / _STANCE_FRACTION[mode], 0.0, 1.0)) ** 2
        track.add(side + "femur", 0, style["hip_abd"] - 4.0 * stance)
        track.add(side + "femur", 2, -style["toe_out"])
        track.add(side + "foot", 2, -0.5 * style["toe_out"])


def _upper_body(track: Track, s_left: np.ndarray, mode: str, amp: np.ndarray, style: dict) -> None:
    """Counter-rotating pelvis and thorax, trunk lean, and arms swinging against the legs."""
    c1 = np.cos(2.0 * np.pi * s_left)
    c2 = np.cos(4.0 * np.pi * s_left)
    run = mode != "walk"
    pelvis_yaw, thorax_yaw = amp * (9.0 if run else 5.0), amp * (7.0 if run else 4.0)
    track.add("root", 2, -pelvis_yaw * c1)
    for j in ("lowerback", "upperback", "thorax"):
        track.add(j, 2, (pelvis_yaw + thorax_yaw) / 3.0 * c1)
        track.add(j, 1, (style["lean"] + 15.0 * style["crouch"]) / 3.0 + amp * 1.0 * c2)
    track.add("root", 0, -amp * 4.0 * np.sin(2.0 * np.pi * s_left))
    track.add("lowerback", 0, amp * 3.0 * np.sin(2.0 * np.pi * s_left))
    track.add("root", 1, style["pelvis_tilt"] + amp * 2.0 * c2)
    for j in ("lowerneck", "upperneck"):
        track.add(j, 2, -thorax_yaw / 2.0 * c1)
        track.add(j, 1, -style["lean"] / 3.0)
    arm_amp = amp * style["arm_swing"]
    for side, sign in (("l", -1.0), ("r", 1.0)):
        carry = side == style["carry"]
        swing = sign * arm_amp * np.cos(2.0 * np.pi * (s_left - 0.04)) * (0.15 if carry else 1.0)
        track.add(side + "humerus", 1, style["arm_flex"] + swing + (12.0 if carry else 0.0))
        track.add(side + "humerus", 0, style["arm_abd"] + (4.0 if run else 0.0))
        track.add(side + "humerus", 2, style["arm_rot"] + (20.0 if carry else 0.0))
        # Softplus rather than max(swing, 0): the elbow bends on the forward swing without a kink.
        elbow = style["elbow"] + 0.25 * (swing + np.sqrt(swing * swing + 25.0))
        track.add(side + "radius", 1, np.full_like(swing, 85.0) if carry else elbow)
        track.add(side + "wrist", 1, 8.0)


def _foot_loads(s_left: np.ndarray, mode: str, stance: float) -> np.ndarray:
    """Load on (lfoot, ltoes, rfoot, rtoes) from the gait phase: heel first, then the ball of the foot.

    Walking hands the load from the trailing to the leading foot over double support (the first
    12 % of each stance); running loads each foot only during its own stance.
    """
    loads = []
    for s in (s_left % 1.0, (s_left + 0.5) % 1.0):
        if mode == "walk":
            ramp = stance - 0.5  # double support: the first (stance - 0.5) of each stance
            on = smootherstep(s / ramp) * (1.0 - smootherstep((s - 0.5) / ramp))
            heel = 1.0 - smootherstep((s - 0.25) / 0.2)
        else:
            on = smootherstep(s / 0.04) * (1.0 - smootherstep((s - stance + 0.04) / 0.04))
            heel = 0.2 * (1.0 - smootherstep((s - 0.02) / 0.08))  # runners load the ball of the foot
        loads += [on * heel, on * (1.0 - heel)]
    return np.stack(loads, axis=1)


def _style(rng: np.random.Generator, mode: str, variant: str) -> dict:
    """Per-subject gait style: posture, arm carriage, toe-out (degrees) and the variant's settings."""
    run = mode != "walk"
    weak = rng.uniform(0.75, 0.9)
    return {
        "crouch": rng.uniform(0.5, 1.0) if variant == "crouched" else 0.0,
        "carry": str(rng.choice(("l", "r"))) if variant == "carrying" else "",
        "leg_gain": ((weak, 1.0) if rng.uniform() < 0.5 else (1.0, weak))
        if variant == "uneven"
        else (1.0, 1.0),
        "lean": rng.uniform(4.0, 12.0) if run else rng.uniform(-1.0, 5.0),
        "pelvis_tilt": rng.uniform(0.0, 6.0),
        "hip_abd": rng.uniform(-1.0, 2.0),
        "toe_out": rng.uniform(0.0, 12.0),
        "knee_bend": rng.uniform(5.0, 15.0) if run else rng.uniform(0.0, 6.0),
        "arm_swing": rng.uniform(30.0, 45.0) if run else rng.uniform(12.0, 26.0),
        "arm_flex": rng.uniform(5.0, 15.0) if run else rng.uniform(-4.0, 6.0),
        "arm_abd": rng.uniform(6.0, 14.0),
        "arm_rot": rng.uniform(5.0, 25.0),
        "elbow": rng.uniform(75.0, 100.0) if run else rng.uniform(10.0, 30.0),
    }


def _yaw_rate(
    rng: np.random.Generator, t: np.ndarray, speed: np.ndarray, kind: str
) -> tuple[np.ndarray, bool]:
    """Heading rate, rad/s, and whether the subject turns on the spot."""
    if kind != "turn":
        return np.deg2rad(6.0) * smooth_noise(rng, t, 1, max_hz=0.15)[:, 0], False
    if rng.uniform() < 0.3:
        # Turning on the spot: ramps into and out of a steady spin of 40-90 deg/s.
        rate = np.deg2rad(rng.uniform(40.0, 90.0)) * rng.choice((-1.0, 1.0))
        ramp = np.clip(np.minimum(t - 0.5, t[-1] - 0.5 - t) / 1.0, 0.0, 1.0)
        return rate * ramp * ramp * (3.0 - 2.0 * ramp), True
    # Curved path: curvature 1/(1.5..5 m), drifting and possibly changing side (S-curves).
    kappa = rng.uniform(0.2, 0.65) * rng.choice((-1.0, 1.0))
    curve = kappa * (0.6 + 0.4 * smooth_noise(rng, t, 1, max_hz=0.12)[:, 0])
    if rng.uniform() < 0.4:
        curve = abs(kappa) * np.sin(2.0 * np.pi * t / rng.uniform(5.0, 9.0) + rng.uniform(0, 2 * np.pi))
    return speed * curve, False


def gait_track(
    rng: np.random.Generator,
    kind: str,
    n_frames: int,
    fps_hz: float,
    body: Body,
    *,
    speed_scale: float | None,
) -> tuple[Track, dict]:
    """Locomotion track for ``kind`` in ("walk", "jog", "run", "turn").

    Args:
        rng: Random generator.
        kind: Locomotion kind.
        n_frames: Number of frames T.
        fps_hz: Frame rate, Hz.
        body: The subject (leg length sets the cadence).
        speed_scale: Target speed as a multiple of the kind's mid-range speed; drawn when None.

    Returns:
        ``(track, params)``: the track and the parameters drawn (speed in m/s and so on).
    """
    lo, hi = GAIT_SPEEDS_MPS[kind]
    speed0 = 0.5 * (lo + hi) * speed_scale if speed_scale is not None else rng.uniform(lo, hi)
    mode = "walk" if kind in ("walk", "turn") else "run"
    variants, odds = _VARIANTS[kind]
    variant = str(rng.choice(variants, p=odds))
    if variant == "backward":
        speed0 *= 0.6
    track = Track.zeros(n_frames, fps_hz)
    t = track.times_s
    speed = speed0 * (1.0 + 0.08 * smooth_noise(rng, t, 1, max_hz=0.2)[:, 0])
    yaw_rate, in_place = _yaw_rate(rng, t, speed, kind)
    if in_place:
        speed = np.full_like(speed, rng.uniform(0.15, 0.35))
    leg = body.leg_length_m
    s_left = _phase(rng, track, speed, mode, leg, backward=variant == "backward")
    # Range of motion that gives the target stride at this cadence (calibrated so that the mean root
    # speed matches the target within ~10 %).
    amp = (
        np.clip(speed / 1.12 * 0.91 / leg, 0.25, 1.2)
        if mode == "walk"
        else np.clip((0.59 + 0.49 * speed / 3.3) * (0.86 if kind == "jog" else 1.0), 0.6, 1.4)
    )
    style = _style(rng, mode, variant)
    _legs(track, s_left, mode, amp, style)
    _upper_body(track, s_left, mode, amp, style)
    # Turning: lean into the curve and look where you go.
    lean = np.rad2deg(np.arctan(speed * yaw_rate / 9.81))
    track.add("root", 0, lean)
    track.add("upperneck", 2, np.rad2deg(0.35 * yaw_rate))
    # Hip angles are relative to the pelvis: cancel pelvic tilt and list so that they move the trunk,
    # not the feet (otherwise the stance foot would be dragged and the root would surge).
    tilt, side = np.rad2deg(track.angles[:, JOINT["root"], 1]), np.rad2deg(track.angles[:, JOINT["root"], 0])
    track.add_sides("femur", 1, tilt, tilt)
    track.add_sides("femur", 0, side, -side)
    track.yaw_rate = yaw_rate
    noise = smooth_noise(rng, t, 12, max_hz=0.8)
    for k, (j, axis, deg) in enumerate(
        (("lfemur", 1, 2.0), ("rfemur", 1, 2.0), ("ltibia", 1, 3.0), ("rtibia", 1, 3.0),
         ("lhumerus", 1, 5.0), ("rhumerus", 1, 5.0), ("lradius", 1, 6.0), ("rradius", 1, 6.0),
         ("upperback", 1, 2.0), ("thorax", 2, 3.0), ("upperneck", 2, 8.0), ("head", 1, 5.0))
    ):  # fmt: skip
        track.add(j, axis, deg * noise[:, k])
    stance = _STANCE_FRACTION[mode] + (0.07 if kind == "jog" else 0.0)
    track.contact = _foot_loads(s_left, mode, stance)
    track.contact_mix[:] = 1.0
    if mode == "run":
        in_stance = ((s_left % 1.0) < stance) | (((s_left + 0.5) % 1.0) < stance)
        track.support = in_stance.astype(np.float64)
    plant_stance_feet(track, body, smoothing_s=GAIT_AVERAGING_S)
    return track, {"speed_mps": float(speed0), "in_place": in_place, "variant": variant}
