"""Procedural monkey: the 13-joint ``monkey13`` topology of markerless primate studios, walking, climbing, sitting.

The 13 joints are those of OpenMonkeyStudio-style annotation: nose, head, neck, both shoulders and hands,
the hip, both knees and feet, and the tail. The motions reuse two kinematic bodies the project already
has, resized to a macaque (0.45-0.6 m from hip to neck) with their own limb proportions:

* ``walk``: quadrupedal locomotion, from the procedural quadruped's walk or turn (shoulder -> front paw
  becomes shoulder -> hand, with the elbow dropped; hip -> knee -> hind paw becomes hip -> knee -> foot);
* ``climb``: the same gait on a vertical surface: the body is turned so that its forward axis points up,
  and it climbs (a fifth of the gait's distance, so that it stays within a cage's height);
* ``sit``: sitting upright and reaching, from the procedural human's idle and gesture motions (CMU-31),
  scaled down, with the hip lowered to the floor and a tail lying behind.

World frame: metres, z up, floor at z = 0.
"""

from __future__ import annotations

import numpy as np

from gttdata.mocap.motion import Motion
from gttdata.mocap.procedural._request import check_request, draw_scale

__all__ = ["MONKEY_KINDS", "generate_monkey_motion"]

#: Motion kinds of :func:`generate_monkey_motion`.
MONKEY_KINDS: tuple[str, ...] = ("walk", "climb", "sit")

#: Joint of ``quadruped36`` each ``monkey13`` joint is read from, for the quadrupedal kinds.
_FROM_QUADRUPED = {
    "nose": "nose",
    "head": "head",
    "neck": "withers",
    "right_shoulder": "right_shoulder",
    "right_hand": "right_front_paw",
    "left_shoulder": "left_shoulder",
    "left_hand": "left_front_paw",
    "hip": "pelvis",
    "right_knee": "right_knee",
    "right_foot": "right_hind_paw",
    "left_knee": "left_knee",
    "left_foot": "left_hind_paw",
    "tail": "tail5",
}

#: CMU-31 joints each ``monkey13`` joint is read from (mean of several), for the upright kinds.
_FROM_CMU = {
    "nose": ("head",),
    "head": ("head", "upperneck"),
    "neck": ("lhumerus", "rhumerus"),
    "right_shoulder": ("rhumerus",),
    "right_hand": ("rhand",),
    "left_shoulder": ("lhumerus",),
    "left_hand": ("lhand",),
    "hip": ("root",),
    "right_knee": ("rtibia",),
    "right_foot": ("rfoot",),
    "left_knee": ("ltibia",),
    "left_foot": ("lfoot",),
    "tail": ("root",),
}


def _quadrupedal(
    kind: str, rng: np.random.Generator, seed: int, duration_s: float, fps_hz: float
) -> np.ndarray:
    from gttdata.mocap.procedural._quadruped import generate_quadruped_motion
    from gttdata.skeletons import QUADRUPED36_JOINTS, monkey13

    gait = "turn" if rng.random() < 0.3 and kind == "walk" else "walk"
    q = generate_quadruped_motion(gait, seed=seed, duration_s=duration_s, fps_hz=fps_hz, body_scale=0.8)
    idx = {n: i for i, n in enumerate(QUADRUPED36_JOINTS)}
    pos = np.stack([q.positions[:, idx[_FROM_QUADRUPED[n]]] for n in monkey13().joint_names], axis=1)
    # A monkey's arms are long next to a dog's front legs: lengthen shoulder -> hand by 20 %, down.
    for s in ("left", "right"):
        sh, ha = monkey13().index(f"{s}_shoulder"), monkey13().index(f"{s}_hand")
        pos[:, ha] = pos[:, sh] + 1.2 * (pos[:, ha] - pos[:, sh])
    pos[..., 2] -= pos[..., 2].min()
    if kind == "climb":
        # Turn the body so its mean forward axis points up: it walks up a wall facing +x.
        fwd = pos[:, monkey13().index("neck")] - pos[:, monkey13().index("hip")]
        h = np.mean(fwd[:, :2], axis=0)
        yaw = np.arctan2(h[1], h[0])
        c, s_ = np.cos(-yaw), np.sin(-yaw)
        Rz = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        Ry = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # +x (forward) -> +z (up)
        pos = pos @ (Ry @ Rz).T
        # Cage walls are a few metres high: keep a fifth of the climb, so that the animal stays in view
        # for the whole motion (a per-frame translation: every segment keeps its length).
        hip = pos[:, monkey13().index("hip"), 2]
        pos[..., 2] -= 0.8 * (hip - hip[0])[:, None]
        pos[..., 2] -= pos[..., 2].min() - 0.2
    return pos


def _upright(rng: np.random.Generator, seed: int, duration_s: float, fps_hz: float) -> np.ndarray:
    from gttdata.mocap.procedural import generate_motion
    from gttdata.skeletons import CMU31_JOINTS, monkey13

    kind = "idle" if rng.random() < 0.5 else "gesture"
    m = generate_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
    idx = {n: i for i, n in enumerate(CMU31_JOINTS)}
    pos = np.stack(
        [m.positions[:, [idx[c] for c in _FROM_CMU[n]]].mean(axis=1) for n in monkey13().joint_names], axis=1
    )
    sk = monkey13()
    hip, neck = sk.index("hip"), sk.index("neck")
    trunk = float(np.median(np.linalg.norm(pos[:, neck] - pos[:, hip], axis=-1)))
    pos *= 0.3 / max(trunk, 1e-6)  # a person's trunk to a macaque's (hip to neck about 0.3 m)
    for s in (
        "left",
        "right",
    ):  # and shorter arms: shoulder to hand 0.75 of a person's, relative to the trunk
        sh, ha = sk.index(f"{s}_shoulder"), sk.index(f"{s}_hand")
        pos[:, ha] = pos[:, sh] + 0.75 * (pos[:, ha] - pos[:, sh])
    # Sitting: the hip on the floor, knees up in front, feet in front of the hip.
    fwd = pos[:, sk.index("nose")] - pos[:, neck]
    fwd[:, 2] = 0.0
    fwd /= np.maximum(np.linalg.norm(fwd, axis=-1, keepdims=True), 1e-9)
    drop = pos[:, hip, 2] - 0.05
    pos[..., 2] -= drop[:, None]
    for s in ("left", "right"):
        kn, ft = sk.index(f"{s}_knee"), sk.index(f"{s}_foot")
        side = pos[:, kn] - pos[:, hip]
        side -= np.sum(side * fwd, axis=-1, keepdims=True) * fwd
        side[:, 2] = 0.0
        pos[:, kn] = pos[:, hip] + side + 0.12 * fwd + np.array([0.0, 0.0, 0.12])
        pos[:, ft] = pos[:, hip] + side + 0.2 * fwd + np.array([0.0, 0.0, 0.0])
    pos[:, sk.index("nose")] = pos[:, sk.index("head")] + 0.06 * fwd
    pos[:, sk.index("tail")] = pos[:, hip] - 0.35 * fwd + np.array([0.0, 0.0, -0.04])
    pos[..., 2] -= min(0.0, float(pos[..., 2].min()))
    return pos


def generate_monkey_motion(kind: str, *, seed: int, duration_s: float = 6.0, fps_hz: float = 120.0) -> Motion:
    """Synthesize one monkey motion on :func:`gttdata.skeletons.monkey13`, deterministically from ``seed``.

    Args:
        kind: One of :data:`MONKEY_KINDS`.
        seed: Non-negative seed.
        duration_s: Length in seconds.
        fps_hz: Frame rate, Hz.

    Returns:
        A Motion in metres, z up, floor at z = 0, centred on the origin in xy.

    Example:
        >>> m = generate_monkey_motion("climb", seed=1, duration_s=1.0)
        >>> m.positions.shape, m.skeleton.name
        ((121, 13, 3), 'monkey13')
    """
    from gttdata.skeletons import monkey13

    check_request("monkey", kind, MONKEY_KINDS, seed, duration_s, fps_hz)
    rng = np.random.default_rng([int(seed), 0x6D6F6E6B])
    size = draw_scale(rng, None, "body_scale", draw=(0.85, 1.15), allowed=(0.5, 2.0))
    if kind == "sit":
        pos = _upright(rng, seed, duration_s, fps_hz)
    else:
        pos = _quadrupedal(kind, rng, seed, duration_s, fps_hz)
    pos = pos * size
    pos[..., :2] -= pos[:, 0, :2].mean(axis=0)
    return Motion(
        positions=pos,
        fps_hz=float(fps_hz),
        skeleton=monkey13(),
        name=f"procedural/monkey/{kind}/s{int(seed)}",
        provenance={
            "source": "procedural-monkey",
            "kind": kind,
            "seed": int(seed),
            "duration_s": float(duration_s),
            "fps_hz": float(fps_hz),
            "body_scale": round(size, 4),
        },
    )
