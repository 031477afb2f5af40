"""Root path from ground contact: feet on the floor, no foot skating, ballistic flight phases."""

from __future__ import annotations

import numpy as np

from gttdata.mocap.procedural._body import FOOT_JOINTS, Body, forward_kinematics
from gttdata.mocap.procedural._track import Track, hann_smooth

__all__ = ["GAIT_AVERAGING_S", "place_on_ground"]

_G_MPS2 = 9.81
# Softness of the lowest-foot choice, metres: keeps the root height smooth when support moves from
# heel to toe or from one foot to the other.
_CONTACT_SOFTNESS_M = 0.006
# Half-width of the window over which the root blends between stance and flight, seconds.
_FLIGHT_BLEND_S = 0.04
#: Window over which the root speed of gaits is averaged, seconds.
GAIT_AVERAGING_S = 1.1


def _softmin(h: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """Smooth minimum over the last axis and its weights (softmax of ``-h / tau``)."""
    m = h.min(axis=-1, keepdims=True)
    e = np.exp(-(h - m) / tau)
    s = e.sum(axis=-1, keepdims=True)
    return (m - tau * np.log(s))[..., 0], e / s


def _flight_gaps(support: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[a, b)`` of frames with support below 0.5 that have support on both sides."""
    off = np.concatenate(([0], (support < 0.5).astype(np.int8), [0]))
    d = np.diff(off)
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if a > 0 and b < support.size]


def _stance_weight(support: np.ndarray, gaps: list[tuple[int, int]], half: int) -> np.ndarray:
    """Weight of the contact solution: 1 in stance, 0 in flight, a smooth (Hann) ramp between."""
    mask = np.ones(support.size)
    for a, b in gaps:
        mask[a:b] = 0.0
    return hann_smooth(mask[:, None], half)[:, 0]


def _bridge(y: np.ndarray, gaps: list[tuple[int, int]], half: int, dt: float, gravity: float) -> np.ndarray:
    """Replace ``y`` over each gap (extended by ``half`` frames) by a parabola through the gap ends.

    The parabola has curvature ``-gravity`` and meets ``y`` at the last stance frame before and the
    first stance frame after the gap (a straight line for ``gravity = 0``).
    """
    out = y.copy()
    n = y.shape[0]
    for a, b in gaps:
        i0, i1 = a - 1, b
        lo, hi = max(i0 - half, 0), min(i1 + half + 1, n)
        t = (np.arange(lo, hi) - i0) * dt
        span = (i1 - i0) * dt
        u = (t / span).reshape((-1,) + (1,) * (y.ndim - 1))
        line = (1.0 - u) * y[i0] + u * y[i1]
        out[lo:hi] = line + (0.5 * gravity * t * (span - t)).reshape(u.shape)
    return out


def place_on_ground(track: Track, body: Body, *, initial_heading: float) -> tuple[np.ndarray, np.ndarray]:
    """World joint positions of a track, with the root path derived from foot contact.

    The body-frame pose comes from forward kinematics. The root height keeps the lowest foot joint
    at its flat-foot clearance while the track has support, and follows a gravity parabola through
    flight phases. The horizontal root velocity is the one that keeps the supporting foot still
    on the floor (foot locking), including the heading rotation; in flight it is interpolated and
    ``track.flight_vel`` is added.

    Args:
        track: The kinematic track.
        body: The subject.
        initial_heading: Heading at the first frame, radians from the world x axis.

    Returns:
        ``(positions, heading)``: world positions, metres, shape ``(T, J, 3)`` (z up, floor at 0,
        root starting at the origin in xy); heading per frame, radians, shape ``(T,)``.
    """
    dt = 1.0 / track.fps_hz
    local = forward_kinematics(track.local_channels(), body.offsets, body.skeleton.parents)
    feet = local[:, FOOT_JOINTS]  # (T, 4, 3), relative to the root, heading frame
    low, w_feet = _softmin(feet[..., 2] - body.clearances, _CONTACT_SOFTNESS_M)
    contact_z = -low

    heading = initial_heading + np.concatenate(
        ([0.0], np.cumsum(0.5 * (track.yaw_rate[1:] + track.yaw_rate[:-1])) * dt)
    )
    gaps = _flight_gaps(track.support)
    half = int(round(_FLIGHT_BLEND_S * track.fps_hz))
    w = _stance_weight(track.support, gaps, half)

    # Root height: contact solution in stance, parabola in flight, never letting a foot sink.
    ballistic = _bridge(contact_z, gaps, half, dt, _G_MPS2)
    z = w * contact_z + (1.0 - w) * ballistic
    z = contact_z + _CONTACT_SOFTNESS_M * (
        np.logaddexp(0.0, (z - contact_z) / _CONTACT_SOFTNESS_M) - np.log(2.0)
    )

    # Foot locking in the heading frame: v_root = -(d/dt foot + yaw_rate x foot) of the supporting foot.
    foot_vel = np.gradient(feet[..., :2], dt, axis=0)
    spin = track.yaw_rate[:, None, None] * np.stack([-feet[..., 1], feet[..., 0]], axis=-1)
    load = track.contact.sum(axis=1, keepdims=True)
    mix = track.contact_mix[:, None] * (load > 1e-6)
    w_feet = mix * track.contact / np.maximum(load, 1e-6) + (1.0 - mix) * w_feet
    v_lock = -np.einsum("tf,tfc->tc", w_feet, foot_vel + spin)
    # Gaits: average over about two steps (as plant_stance_feet assumed) so the pelvis speed is
    # steady; the average is weighted by foot load, so flight phases do not drag it down.
    half_avg = int(round(GAIT_AVERAGING_S * track.fps_hz / 2))
    g = track.contact_mix[:, None] * load + (1.0 - track.contact_mix[:, None])
    v_avg = hann_smooth(g * v_lock, half_avg) / np.maximum(hann_smooth(g, half_avg), 1e-9)
    v_lock += track.contact_mix[:, None] * (v_avg - v_lock)
    v_air = _bridge(v_lock, gaps, half, dt, 0.0) + track.flight_vel
    v_body = w[:, None] * v_lock + (1.0 - w[:, None]) * v_air
    c, s = np.cos(heading), np.sin(heading)
    v_world = np.stack([c * v_body[:, 0] - s * v_body[:, 1], s * v_body[:, 0] + c * v_body[:, 1]], axis=-1)
    xy = np.concatenate((np.zeros((1, 2)), np.cumsum(0.5 * (v_world[1:] + v_world[:-1]), axis=0) * dt))

    world = np.empty_like(local)
    world[..., 0] = c[:, None] * local[..., 0] - s[:, None] * local[..., 1] + xy[:, None, 0]
    world[..., 1] = s[:, None] * local[..., 0] + c[:, None] * local[..., 1] + xy[:, None, 1]
    world[..., 2] = local[..., 2] + z[:, None]
    return world, heading
