"""Procedural quadruped: the 36-joint (``quadruped36``) four-legged animal that walks, trots, turns and sits.

The body is kinematic: a spine, neck and tail built from fixed-length segments and smooth angles, and
four legs whose paws follow a gait's footfall pattern. A paw in stance stays at its foothold on the
floor; in swing it moves on an arc to the next foothold, placed under the shoulder or hip at the
middle of the next stance. Each leg (upper, lower, metapodial segment) is solved by two-bone inverse
kinematics, so every bone keeps its length; a target out of reach is clamped and then the paw slides
(rare at the sampled speeds).

World frame: metres, z up, floor at z = 0; the body's forward axis is x at heading 0.
"""

from __future__ import annotations

import numpy as np

from gttdata.mocap.motion import Motion
from gttdata.mocap.procedural._request import check_request, draw_scale
from gttdata.skeletons import QUADRUPED36_JOINTS, quadruped36

__all__ = ["QUADRUPED_KINDS", "generate_quadruped_motion"]

#: Motion kinds of :func:`generate_quadruped_motion`.
QUADRUPED_KINDS: tuple[str, ...] = ("walk", "trot", "turn", "sit")

_SPINE = ("pelvis", "spine1", "spine2", "spine3", "withers")
_NECK = ("neck1", "neck2", "head", "nose")
_TAIL = tuple(f"tail{k}" for k in range(1, 6))
_FRONT = ("shoulder", "elbow", "front_wrist", "front_paw", "front_toe")
_HIND = ("hip", "knee", "hock", "hind_paw", "hind_toe")


def _smooth_noise(rng: np.random.Generator, t: np.ndarray, n: int = 4, f_max: float = 0.6) -> np.ndarray:
    """A smooth zero-mean signal in [-1, 1] from a few random sinusoids, shape like ``t``."""
    f = rng.uniform(0.1, f_max, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    return np.sum(np.sin(2 * np.pi * f[:, None] * t[None] + ph[:, None]), axis=0) / n


def _rot_z(a: np.ndarray) -> np.ndarray:
    """Rotations about z, shape ``(T, 3, 3)``."""
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    return R


def _dir(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Unit vectors at heading ``yaw`` and elevation ``pitch`` (radians), shape ``(T, 3)``."""
    return np.stack([np.cos(pitch) * np.cos(yaw), np.cos(pitch) * np.sin(yaw), np.sin(pitch)], axis=-1)


def _two_bone(root: np.ndarray, target: np.ndarray, l1: float, l2: float, bend: np.ndarray):
    """Middle joint and (clamped) end of a two-bone chain from ``root`` toward ``target``.

    Args:
        root: Chain start, shape ``(T, 3)``.
        target: Point the chain reaches toward, shape ``(T, 3)``.
        l1: Length of the first segment.
        l2: Length of the second segment.
        bend: Direction the middle joint bends toward, shape ``(T, 3)`` (need not be orthogonal).

    Returns:
        ``(mid, end)``, each ``(T, 3)``; ``|mid - root| = l1`` and ``|end - mid| = l2`` exactly.
    """
    v = target - root
    d = np.linalg.norm(v, axis=-1, keepdims=True)
    u = v / np.maximum(d, 1e-9)
    d = np.clip(d, abs(l1 - l2) + 1e-4, l1 + l2 - 1e-4)
    end = root + u * d
    a = (l1**2 - l2**2 + d**2) / (2 * d)
    h = np.sqrt(np.maximum(l1**2 - a**2, 0.0))
    w = bend - np.sum(bend * u, axis=-1, keepdims=True) * u
    w /= np.maximum(np.linalg.norm(w, axis=-1, keepdims=True), 1e-9)
    return root + a * u + h * w, end


def _gait(kind: str, rng: np.random.Generator, s: float):
    """Speed (m/s), stride frequency (Hz), duty factor, per-leg phase offsets (LF, RF, LH, RH), turn rate."""
    if kind == "trot":
        v = rng.uniform(1.2, 2.0) * s
        return v, rng.uniform(2.0, 2.6) / np.sqrt(s), 0.45, (0.0, 0.5, 0.5, 0.0), 0.0
    if kind == "sit":
        return 0.0, 1.0, 1.0, (0.0, 0.0, 0.0, 0.0), 0.0
    v = rng.uniform(0.4, 0.7) * s
    omega = rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 1.0) if kind == "turn" else rng.uniform(-0.1, 0.1)
    return v, rng.uniform(1.2, 1.6) / np.sqrt(s), 0.7, (0.25, 0.75, 0.0, 0.5), omega


def generate_quadruped_motion(
    kind: str, *, seed: int, duration_s: float = 6.0, fps_hz: float = 120.0, body_scale: float | None = None
) -> Motion:
    """Synthesize one quadruped motion, deterministically from ``seed``.

    Args:
        kind: One of :data:`QUADRUPED_KINDS`.
        seed: Non-negative seed.
        duration_s: Length in seconds (``round(duration_s * fps_hz) + 1`` frames).
        fps_hz: Frame rate, Hz.
        body_scale: Size relative to a 0.55 m (withers height) dog, in [0.5, 2]; drawn when None.

    Returns:
        A Motion on :func:`gttdata.skeletons.quadruped36`, metres, z up, floor at z = 0, centred on the origin in xy.
    """
    check_request("quadruped", kind, QUADRUPED_KINDS, seed, duration_s, fps_hz)
    rng = np.random.default_rng([int(seed), 0x71756164])
    s = draw_scale(rng, body_scale, "body_scale", draw=(0.6, 1.4), allowed=(0.5, 2.0))
    g = s * rng.uniform(0.93, 1.07, 12)  # per-segment proportion noise
    trunk, neck_l, head_l, muzzle, ear_off = 0.50 * g[0], 0.12 * g[1], 0.10 * g[2], 0.09 * g[3], 0.05 * g[2]
    f1, f2, f3, toe = 0.16 * g[4], 0.16 * g[5], 0.07 * g[6], 0.035 * g[6]
    h1, h2, h3 = 0.19 * g[7], 0.19 * g[8], 0.10 * g[9]
    tail_seg, half_w = 0.07 * g[10], 0.07 * g[11]
    paw_z = 0.02 * s

    pad = 3.0
    n = int(round(duration_s * fps_hz)) + 1
    t = (np.arange(n + 2 * int(pad * fps_hz)) - int(pad * fps_hz)) / fps_hz
    T = t.shape[0]
    v, freq, duty, offsets, omega = _gait(kind, rng, s)
    heading = (
        rng.uniform(-np.pi, np.pi) + omega * t + 0.15 * _smooth_noise(rng, t, f_max=0.2) * (kind != "sit")
    )
    fwd = _dir(heading, np.zeros(T))
    root_xy = np.cumsum(fwd * v / fps_hz, axis=0)
    root_xy -= root_xy[int(pad * fps_hz)]

    # Heights: legs bent to ~85 % of their reach in stance; sitting lowers and pitches the pelvis.
    hip_h = 0.85 * (h1 + h2) + h3 + paw_z
    sh_h = 0.85 * (f1 + f2) + f3 + paw_z
    sit = np.zeros(T)
    if kind == "sit":
        t0, t1 = rng.uniform(0.3, 0.45) * duration_s, rng.uniform(0.75, 0.9) * duration_s
        ramp = rng.uniform(0.6, 1.0)
        sit = np.clip((t - t0) / ramp, 0, 1) - np.clip((t - t1) / ramp, 0, 1)
        sit = sit * sit * (3 - 2 * sit)  # smoothstep: sit down, stay, stand up
    bob = 0.01 * s * np.sin(2 * np.pi * 2 * freq * t) * (kind != "sit")
    pelvis_h = hip_h * (1 - 0.55 * sit) + bob
    pitch = np.arcsin(
        np.clip((sh_h - pelvis_h + 0.03 * s) / trunk, -0.9, 0.9)
    )  # trunk pitch from the heights
    pelvis = np.concatenate([root_xy[:, :2], pelvis_h[:, None]], axis=1)
    pelvis[:, :2] -= fwd[:, :2] * (0.25 * trunk * sit)[:, None]  # the pelvis slides back as it sits

    # Spine: 4 equal segments, a lateral bend with the turn rate and a little sway.
    bend = np.clip(omega * 0.12, -0.3, 0.3) + 0.05 * _smooth_noise(rng, t)
    joints: dict[str, np.ndarray] = {"pelvis": pelvis}
    p = pelvis
    for k, name in enumerate(_SPINE[1:]):
        yaw = heading + bend * (k + 0.5) / 4
        p = p + _dir(yaw, pitch) * (trunk / 4)
        joints[name] = p
    chest_yaw = heading + bend
    # Neck and head: pitch up more when sitting; the head looks around.
    look = 0.35 * _smooth_noise(rng, t, f_max=0.4)
    neck_pitch = 0.6 + 0.3 * sit + 0.1 * _smooth_noise(rng, t)
    p = joints["withers"]
    for name, length, pt in (("neck1", neck_l, neck_pitch), ("neck2", neck_l, neck_pitch * 0.8)):
        p = p + _dir(chest_yaw + look * 0.5, pt) * length
        joints[name] = p
    head_yaw = chest_yaw + look
    joints["head"] = p + _dir(head_yaw, neck_pitch * 0.3) * head_l
    head_fwd = _dir(head_yaw, -0.35 + 0.2 * sit)
    joints["nose"] = joints["head"] + head_fwd * muzzle
    lateral = _dir(head_yaw + np.pi / 2, np.zeros(T))
    up = np.cross(head_fwd, lateral)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        joints[f"{side}_ear"] = joints["head"] + ear_off * (sign * lateral + 0.6 * up - 0.4 * head_fwd)
    # Tail: droops behind the pelvis and wags.
    wag = (0.5 if kind != "sit" else 0.2) * np.sin(
        2 * np.pi * rng.uniform(1.5, 3.0) * t + rng.uniform(0, 6.3)
    )
    p = pelvis
    for k, name in enumerate(_TAIL):
        p = p + _dir(heading + np.pi + wag * (k + 1) / 5, (-0.3 - 0.12 * k) * (1 - 0.8 * sit)) * tail_seg
        joints[name] = p

    # Legs.
    body_lat = _dir(heading + np.pi / 2, np.zeros(T))
    chest_lat = _dir(chest_yaw + np.pi / 2, np.zeros(T))
    cycle = freq * t
    legs = [("left", "front", 1.0, offsets[0]), ("right", "front", -1.0, offsets[1])]
    legs += [("left", "hind", 1.0, offsets[2]), ("right", "hind", -1.0, offsets[3])]
    for side, end, sign, off in legs:
        front = end == "front"
        base = (
            joints["withers"] + (chest_lat * sign * half_w) - np.array([0, 0, 0.08 * s])
            if front
            else (pelvis + body_lat * sign * half_w)
        )
        heading_leg = chest_yaw if front else heading
        leg_fwd = _dir(heading_leg, np.zeros(T))
        neutral = base.copy()
        neutral[:, 2] = paw_z
        neutral += leg_fwd * (0.03 * s if front else -0.02 * s)
        paw = _footfalls(neutral, cycle + off, duty, 0.06 * s * (kind == "trot") + 0.05 * s)
        names = _FRONT if front else _HIND
        l1, l2, l3 = (f1, f2, f3) if front else (h1, h2, h3)
        # The metapodial segment (wrist/hock to paw) leans back by a fixed angle in the leg's plane.
        meta = _dir(heading_leg, np.full(T, np.pi / 2)) * np.cos(0.25) - leg_fwd * np.sin(0.25)
        if not front:  # hind: the hock sits behind the paw
            meta = _dir(heading_leg, np.full(T, np.pi / 2)) * np.cos(0.35) - leg_fwd * np.sin(0.35)
        mid_target = paw + meta * l3
        bend_dir = -leg_fwd if front else leg_fwd  # elbow points back, knee (stifle) forward
        mid, lower = _two_bone(base, mid_target, l1, l2, bend_dir)
        paw = lower - meta * l3
        joints[f"{side}_{names[0]}"] = base
        joints[f"{side}_{names[1]}"] = mid
        joints[f"{side}_{names[2]}"] = lower
        joints[f"{side}_{names[3]}"] = paw
        joints[f"{side}_{names[4]}"] = paw + leg_fwd * toe

    crop = slice(int(pad * fps_hz), int(pad * fps_hz) + n)
    pos = np.stack([joints[name][crop] for name in QUADRUPED36_JOINTS], axis=1)
    pos[..., :2] -= pos[:, 0, :2].mean(axis=0)
    return Motion(
        positions=pos,
        fps_hz=float(fps_hz),
        skeleton=quadruped36(),
        name=f"procedural/quadruped/{kind}/s{int(seed)}",
        provenance={
            "source": "procedural-quadruped",
            "kind": kind,
            "seed": int(seed),
            "duration_s": float(duration_s),
            "fps_hz": float(fps_hz),
            "body_scale": round(s, 4),
            "speed_mps": round(float(v), 4),
            "stride_hz": round(float(freq), 4),
            "turn_rate_rad_s": round(float(omega), 4),
        },
    )


def _footfalls(neutral: np.ndarray, phase: np.ndarray, duty: float, lift: float) -> np.ndarray:
    """Paw positions: planted at a foothold in stance, on an arc between footholds in swing.

    Args:
        neutral: The leg's neutral paw point under its shoulder or hip, per frame, shape ``(T, 3)``.
        phase: Gait phase in cycles (stance when ``phase mod 1 < duty``), shape ``(T,)``.
        duty: Stance fraction of a cycle; 1 keeps the paw planted at its first foothold.
        lift: Swing height, metres.

    Returns:
        Paw positions, shape ``(T, 3)``.
    """
    T = neutral.shape[0]
    if duty >= 1.0:
        return np.repeat(neutral[:1], T, axis=0)
    cyc = np.floor(phase).astype(np.int64)
    frac = phase - cyc
    # Foothold of cycle c: the neutral point at the middle of that cycle's stance (nearest frame).
    cycles = np.arange(cyc.min() - 1, cyc.max() + 2)
    mid_phase = cycles + duty / 2
    mid_idx = np.clip(np.searchsorted(phase, mid_phase), 0, T - 1)
    hold = neutral[mid_idx]
    # Stretch the first and last footholds from the motion's ends (their mid-stance may lie outside).
    k = cyc - cycles[0]
    out = hold[k].copy()
    swing = frac >= duty
    s = (frac[swing] - duty) / (1 - duty)
    s_smooth = s * s * (3 - 2 * s)
    a, b = hold[k[swing]], hold[k[swing] + 1]
    out[swing] = a + (b - a) * s_smooth[:, None]
    out[swing, 2] += lift * np.sin(np.pi * s)
    return out
