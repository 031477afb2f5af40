"""Stance-foot planting for gait tracks: hip corrections that make the loaded foot sweep back at pelvis speed."""

from __future__ import annotations

import numpy as np

from gttdata.mocap.procedural._body import FOOT_JOINTS, JOINT, Body, forward_kinematics
from gttdata.mocap.procedural._track import Track, hann_smooth, smootherstep

__all__ = ["plant_stance_feet"]

# Correction passes: each linearises the foot velocity around the previous pass's pose.
_PASSES = 2
# Swing time over which a correction left at the end of the last stance is released, seconds.
_RELEASE_S = 0.4


def _hold_and_release(integral: np.ndarray, load: np.ndarray, fps_hz: float) -> np.ndarray:
    """The part of an integrated correction that should remain applied, shape ``(T,)``.

    The correction starts at 0 when a foot is loaded, follows ``integral`` while it stays loaded,
    and returns to 0 with a C2 ramp over the swing that follows, so the swing ends where the
    uncorrected gait cycle puts the foot.
    """
    on = np.concatenate(([0], (load > 0.0).astype(np.int8), [0]))
    d = np.diff(on)
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    n = integral.size
    base = integral.copy()  # correction = integral - base
    for k, (a, b) in enumerate(zip(starts, stops, strict=True)):
        base[a:b] = integral[a]
        nxt = int(starts[k + 1]) if k + 1 < starts.size else min(n, int(b) + int(_RELEASE_S * fps_hz))
        if nxt > b:
            ramp = smootherstep((np.arange(b, nxt) - b + 1) / (nxt - b))
            base[b:nxt] = integral[a] + ramp * (integral[b - 1] - integral[a])
    return integral - base


def plant_stance_feet(track: Track, body: Body, *, smoothing_s: float) -> None:
    """Adjust hip flexion and abduction so each loaded foot moves against the pelvis at its mean speed.

    Hand-made gait cycles do not keep the supporting foot's velocity relative to the pelvis constant,
    which, with the root derived from foot contact, makes the pelvis surge and the feet slip. For
    each leg this integrates the hip rotation rate that cancels the difference between the foot's
    velocity and minus the smoothed pelvis velocity (lever arm = hip-to-contact height) while the
    foot carries load (``track.contact``), and releases the correction during the swing.

    Args:
        track: Gait track with ``contact`` loads; modified in place.
        body: The subject.
        smoothing_s: Window of the pelvis velocity average, seconds (as used by the ground stage).
    """
    dt = 1.0 / track.fps_hz
    loads = track.contact
    half = int(round(smoothing_s * track.fps_hz / 2))
    # Normalised convolution: the average skips flight phases, where no foot carries load.
    total = np.maximum(hann_smooth(loads.sum(axis=1, keepdims=True), half), 1e-9)
    for _ in range(_PASSES):
        pos = forward_kinematics(track.local_channels(), body.offsets, body.skeleton.parents)
        feet = pos[:, FOOT_JOINTS]
        spin = track.yaw_rate[:, None, None] * np.stack([-feet[..., 1], feet[..., 0]], axis=-1)
        vel = np.gradient(feet[..., :2], dt, axis=0) + spin  # (T, 4, 2), heading frame
        v_ref = -hann_smooth(np.einsum("tf,tfc->tc", loads, vel), half) / total
        for side, cols, out in (("l", [0, 1], 1.0), ("r", [2, 3], -1.0)):
            load = loads[:, cols].sum(axis=1)
            w = loads[:, cols] / np.maximum(load, 1e-9)[:, None]
            u = np.einsum("tf,tfc->tc", w, vel[:, cols])
            contact_z = (w * feet[:, cols, 2]).sum(axis=1)
            lever = np.maximum(pos[:, JOINT[side + "femur"], 2] - contact_z, 0.3)
            # Flexion moves the foot forward (+x); abduction moves it outward (+y left, -y right).
            rate = load[:, None] * (-v_ref - u) / lever[:, None]
            integral = np.cumsum(rate, axis=0) * dt
            flex = _hold_and_release(integral[:, 0], load, track.fps_hz)
            abd = _hold_and_release(integral[:, 1], load, track.fps_hz)
            track.add(side + "femur", 1, np.rad2deg(flex))
            track.add(side + "femur", 0, np.rad2deg(out * abd))
