"""Procedural hand: 21 keypoints (hand-21 order) that grasp, spread, point and wave.

The hand is kinematic. The palm is rigid: the wrist and the base of each finger (thumb CMC, other
fingers MCP) are fixed points of a hand frame. Each finger is a chain of three fixed-length
phalanges whose flexion angles (and the base joint's spread) follow the motion kind; the hand frame
moves and turns smoothly in the world (wave: a side-to-side swing of the forearm). Every bone keeps
its length exactly.

Hand frame: ``x`` from the wrist toward the middle finger, ``y`` toward the thumb, ``z`` out of the
back of the hand (palm faces ``-z``). World frame: metres, z up.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from gttdata.mocap.motion import Motion
from gttdata.mocap.procedural._request import check_request, draw_scale
from gttdata.skeletons import get_skeleton

__all__ = ["HAND_KINDS", "generate_hand_motion"]

#: Motion kinds of :func:`generate_hand_motion`.
HAND_KINDS: tuple[str, ...] = ("grasp", "spread", "point", "wave")

_FINGERS = ("thumb", "index", "middle", "ring", "pinky")
# Base of each finger in the hand frame (metres, reference adult hand), and its rest spread (radians).
_BASE = {
    "thumb": (0.025, 0.025, -0.010),
    "index": (0.085, 0.025, 0.0),
    "middle": (0.090, 0.002, 0.0),
    "ring": (0.085, -0.018, 0.0),
    "pinky": (0.075, -0.036, 0.0),
}
_SPREAD = {"thumb": 0.9, "index": 0.12, "middle": 0.0, "ring": -0.1, "pinky": -0.22}
# Phalanx lengths (proximal, middle, distal), metres.
_LENGTHS = {
    "thumb": (0.040, 0.032, 0.027),
    "index": (0.040, 0.025, 0.020),
    "middle": (0.045, 0.028, 0.022),
    "ring": (0.042, 0.026, 0.021),
    "pinky": (0.033, 0.020, 0.018),
}


def _ease(x: np.ndarray) -> np.ndarray:
    """Smooth 0..1 periodic envelope of a phase in cycles."""
    return 0.5 - 0.5 * np.cos(2 * np.pi * x)


def _angles(kind: str, rng: np.random.Generator, t: np.ndarray):
    """Flexion (T, 5) in [0, 1] of full flexion per finger, and extra spread (T, 5) in radians."""
    T = t.shape[0]
    rate = rng.uniform(0.4, 1.0)
    phase = rate * t + rng.uniform(0, 1)
    flex = np.zeros((T, 5))
    spread = np.zeros((T, 5))
    wiggle = 0.05 * np.sin(2 * np.pi * (rng.uniform(0.3, 0.8, 5) * t[:, None] + rng.uniform(0, 1, 5)))
    if kind == "grasp":
        lag = rng.uniform(0.0, 0.08, 5)  # fingers close one after another
        flex = _ease(phase[:, None] - lag[None]) * rng.uniform(0.75, 1.0)
        flex[:, 0] *= 0.7
    elif kind == "spread":
        env = _ease(phase)[:, None]
        spread = env * np.array([0.35, 0.25, 0.0, -0.2, -0.35]) * rng.uniform(0.7, 1.2)
        flex = 0.15 * (1 - env) + 0.05
    elif kind == "point":
        env = np.clip(2 * _ease(0.5 * phase) - 0.3, 0, 1)[:, None]
        flex = env * np.array([0.6, 0.0, 0.95, 0.95, 0.95]) + (1 - env) * 0.2
    else:  # wave: open hand, fingers nearly straight
        flex = np.full((T, 5), 0.08)
        spread = np.full((T, 5), 0.1) * np.array([1.0, 1.0, 0.0, -1.0, -1.5])
    return np.clip(flex + wiggle, 0, 1), spread


def generate_hand_motion(
    kind: str, *, seed: int, duration_s: float = 6.0, fps_hz: float = 120.0, hand_scale: float | None = None
) -> Motion:
    """Synthesize one hand motion on the hand-21 skeleton, deterministically from ``seed``.

    Args:
        kind: One of :data:`HAND_KINDS`.
        seed: Non-negative seed.
        duration_s: Length in seconds (``round(duration_s * fps_hz) + 1`` frames).
        fps_hz: Frame rate, Hz.
        hand_scale: Size relative to a reference adult hand (wrist to middle tip 0.185 m), in [0.6, 1.5];
            drawn in [0.85, 1.15] when None.

    Returns:
        A Motion on ``get_skeleton("hand21")``: metres, world z up, the wrist about 1.2 m above the
        floor and centred on the origin in xy.
    """
    check_request("hand", kind, HAND_KINDS, seed, duration_s, fps_hz)
    rng = np.random.default_rng([int(seed), 0x68616E64])
    s = draw_scale(rng, hand_scale, "hand_scale", draw=(0.85, 1.15), allowed=(0.6, 1.5))
    n = int(round(duration_s * fps_hz)) + 1
    t = np.arange(n) / fps_hz
    flex, spread = _angles(kind, rng, t)

    # Local joint positions in the hand frame, (T, 21, 3).
    local = np.zeros((n, 21, 3))
    prop = rng.uniform(0.95, 1.05, (5, 3))
    for f, finger in enumerate(_FINGERS):
        base = np.asarray(_BASE[finger]) * s
        yaw = _SPREAD[finger] + spread[:, f]
        if finger == "thumb":
            # The thumb's base bends across the palm (toward -z and the palm's middle) as it flexes.
            d0 = np.stack([np.cos(yaw), np.sin(yaw), np.full(n, -0.5)], axis=-1)
            d0 /= np.linalg.norm(d0, axis=-1, keepdims=True)
            across = np.array([0.3, -1.0, -0.6]) / np.linalg.norm([0.3, -1.0, -0.6])
            max_flex = (0.5, 0.6, 0.8)
        else:
            d0 = np.stack([np.cos(yaw), np.sin(yaw), np.zeros(n)], axis=-1)
            across = np.array([0.0, 0.0, -1.0])
            max_flex = (1.4, 1.6, 1.1)  # MCP, PIP, DIP full flexion, radians
        p = np.broadcast_to(base, (n, 3)).copy()
        local[:, 1 + 4 * f] = p
        theta = np.zeros(n)
        for k in range(3):
            theta = theta + flex[:, f] * max_flex[k]
            d = np.cos(theta)[:, None] * d0 + np.sin(theta)[:, None] * across
            d /= np.linalg.norm(d, axis=-1, keepdims=True)
            p = p + d * (_LENGTHS[finger][k] * s * prop[f, k])
            local[:, 2 + 4 * f + k] = p

    # Hand frame in the world: smooth drift plus the kind's gesture.
    def noise(scale, f_max=0.5, dims=3):
        fr = rng.uniform(0.05, f_max, (4, dims))
        ph = rng.uniform(0, 2 * np.pi, (4, dims))
        return scale * np.sin(2 * np.pi * fr[None] * t[:, None, None] + ph[None]).mean(axis=1)

    wrist = np.array([0.0, 0.0, 1.2]) + noise(0.08)
    rotvec = noise(0.4)
    rotvec[:, 2] += rng.uniform(-np.pi, np.pi)
    base_rot = Rotation.from_euler("y", -np.pi / 2 + rng.uniform(-0.4, 0.4))  # fingers up, palm forward
    if kind == "wave":
        w = 2 * np.pi * rng.uniform(1.2, 2.2) * t
        rotvec[:, 0] += 0.5 * np.sin(w)  # swing about the forearm's normal
        wrist[:, 1] += 0.06 * np.sin(w)
    R = Rotation.from_rotvec(rotvec) * base_rot
    pos = wrist[:, None, :] + np.einsum("tab,tjb->tja", R.as_matrix(), local)
    pos[..., :2] -= pos[:, 0, :2].mean(axis=0)
    return Motion(
        positions=pos,
        fps_hz=float(fps_hz),
        skeleton=get_skeleton("hand21"),
        name=f"procedural/hand/{kind}/s{int(seed)}",
        provenance={
            "source": "procedural-hand",
            "kind": kind,
            "seed": int(seed),
            "duration_s": float(duration_s),
            "fps_hz": float(fps_hz),
            "hand_scale": round(s, 4),
        },
    )
