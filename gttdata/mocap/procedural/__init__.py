"""Built-in procedural motion sources.

Built-in procedural motion sources: seeded kinematic synthesis of human motion on the CMU-31 skeleton
(and the keypoint sets derived from it), of a hand (hand-21) and of a quadruped (quadruped36).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np

from gttdata.mocap.motion import Motion
from gttdata.mocap.procedural._actions import action_track
from gttdata.mocap.procedural._body import Body, sample_body
from gttdata.mocap.procedural._dance import dance_track
from gttdata.mocap.procedural._gait import gait_track
from gttdata.mocap.procedural._ground import place_on_ground
from gttdata.mocap.procedural._hand import HAND_KINDS, generate_hand_motion
from gttdata.mocap.procedural._mixed import mixed_track
from gttdata.mocap.procedural._monkey import MONKEY_KINDS, generate_monkey_motion
from gttdata.mocap.procedural._quadruped import QUADRUPED_KINDS, generate_quadruped_motion
from gttdata.mocap.procedural._track import Track
from gttdata.skeleton import cmu31

__all__ = [
    "HAND_KINDS",
    "MONKEY_KINDS",
    "PROCEDURAL_KINDS",
    "QUADRUPED_KINDS",
    "generate_hand_motion",
    "generate_monkey_motion",
    "generate_motion",
    "generate_quadruped_motion",
    "generate_skeleton_motion",
    "kinds_for_skeleton",
    "random_motion",
]

_log = logging.getLogger(__name__)

#: Motion kinds :func:`generate_motion` knows.
PROCEDURAL_KINDS: tuple[str, ...] = (
    "walk",
    "jog",
    "run",
    "turn",
    "jump",
    "gesture",
    "dance",
    "idle",
    "mixed",
)

# Margin synthesized before and after the returned frames, seconds.
_PAD_S = 0.5

_Generator = Callable[..., tuple[Track, dict]]
_GENERATORS: dict[str, _Generator] = {
    "walk": gait_track,
    "jog": gait_track,
    "run": gait_track,
    "turn": gait_track,
    "jump": action_track,
    "gesture": action_track,
    "idle": action_track,
    "dance": dance_track,
}


def _build_track(
    rng: np.random.Generator, kind: str, n_frames: int, fps_hz: float, body: Body, speed_scale: float | None
) -> tuple[Track, dict]:
    """Dispatch to the kind's generator ("mixed" composes the others)."""
    if kind == "mixed":
        parts = tuple(k for k in PROCEDURAL_KINDS if k != "mixed")
        return mixed_track(rng, parts, n_frames, fps_hz, body, speed_scale=speed_scale, build=_build_track)
    return _GENERATORS[kind](rng, kind, n_frames, fps_hz, body, speed_scale=speed_scale)


def _check_args(
    kind: str,
    seed: int,
    duration_s: float,
    fps_hz: float,
    speed_scale: float | None,
    body_scale: float | None,
) -> None:
    if kind not in PROCEDURAL_KINDS:
        raise ValueError(
            f"unknown procedural motion kind {kind!r}; expected one of {', '.join(PROCEDURAL_KINDS)}"
        )
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration_s must be > 0, got {duration_s}")
    if not (np.isfinite(fps_hz) and fps_hz >= 10.0):
        raise ValueError(f"fps_hz must be >= 10, got {fps_hz}")
    for name, value, lo, hi in (("speed_scale", speed_scale, 0.3, 2.0), ("body_scale", body_scale, 0.7, 1.3)):
        if value is not None and not (np.isfinite(value) and lo <= value <= hi):
            raise ValueError(f"{name} must be None or in [{lo}, {hi}], got {value}")


def generate_motion(
    kind: str,
    *,
    seed: int,
    duration_s: float = 10.0,
    fps_hz: float = 120.0,
    speed_scale: float | None = None,
    body_scale: float | None = None,
) -> Motion:
    """Synthesize one motion of a given kind, deterministically from ``seed``.

    The motion is built as kinematics: a subject (stature and segment proportions drawn from the
    seed, CMU subject-01 proportions on average), anatomical joint angles from a per-kind generator
    (gait cycles, jumps, gestures, dance patterns, idling, or cross-faded segments of these), exact
    forward kinematics (bone lengths constant to rounding), and a root path derived from ground
    contact (feet on the floor, supporting foot planted, ballistic flight). Joint positions follow
    the CMU BVH layout: a joint sits at the start of its bone, so lhipjoint/rhipjoint/lowerback
    coincide with the root, lowerneck and the clavicles with the thorax, lhand/lthumb with the wrist.

    Args:
        kind: One of :data:`PROCEDURAL_KINDS`.
        seed: Non-negative seed; the same arguments always give bit-identical positions.
        duration_s: Length in seconds; the motion has ``round(duration_s * fps_hz) + 1`` frames.
        fps_hz: Frame rate, Hz (at least 10).
        speed_scale: Speed (gaits) or tempo (other kinds) as a multiple of the kind's mid-range
            value, in [0.3, 2]; drawn from the seed when None.
        body_scale: Stature as a multiple of the 1.61 m reference subject (CMU subject 01's
            proportions), in [0.7, 1.3]; drawn from the seed (stature 1.50-1.95 m) when None.
            Segment proportions always vary slightly with the seed.

    Returns:
        A :class:`Motion` on the CMU-31 skeleton: positions in metres, world frame z up with the
        floor at z = 0, root path centred on the origin in xy; named ``procedural/<kind>/s<seed>``,
        with the drawn parameters in ``provenance``.

    Raises:
        ValueError: Unknown kind (the message lists the kinds) or an argument out of range.

    Example:
        >>> m = generate_motion("walk", seed=3, duration_s=2.0)
        >>> m.positions.shape, m.name
        ((241, 31, 3), 'procedural/walk/s3')
    """
    _check_args(kind, seed, duration_s, fps_hz, speed_scale, body_scale)
    rng = np.random.default_rng(int(seed))
    n_frames = int(round(duration_s * fps_hz)) + 1
    body = sample_body(rng, body_scale=body_scale)
    heading0 = float(rng.uniform(-np.pi, np.pi))
    # Synthesize a margin on both sides and crop it: one-sided differences, smoothing windows and
    # flight phases cut by the ends then never reach the returned frames.
    pad = int(round(_PAD_S * fps_hz))
    track, params = _build_track(rng, kind, n_frames + 2 * pad, float(fps_hz), body, speed_scale)
    positions, _ = place_on_ground(track, body, initial_heading=heading0)
    positions = positions[pad : pad + n_frames]
    positions[..., :2] -= positions[:, 0, :2].mean(axis=0)
    provenance = {
        "source": "procedural",
        "kind": kind,
        "seed": int(seed),
        "duration_s": float(duration_s),
        "fps_hz": float(fps_hz),
        "speed_scale": speed_scale,
        "body_scale": body_scale,
        "stature_m": round(body.stature_m, 4),
        "initial_heading_rad": round(heading0, 4),
        "mean_root_speed_mps": round(
            float(np.linalg.norm(np.diff(positions[:, 0, :2], axis=0), axis=-1).mean() * fps_hz), 4
        ),
        **params,
    }
    _log.debug("generated procedural %s seed=%d: %d frames", kind, seed, n_frames)
    return Motion(
        positions=positions,
        fps_hz=float(fps_hz),
        skeleton=cmu31(),
        name=f"procedural/{kind}/s{int(seed)}",
        provenance=provenance,
    )


def random_motion(
    seed: int, *, duration_s: float = 10.0, fps_hz: float = 120.0, kinds: tuple[str, ...] | None = None
) -> Motion:
    """A motion of a kind drawn from ``seed``; equal to ``generate_motion(kind, seed=seed, ...)``.

    Args:
        seed: Non-negative seed; picks the kind, then every parameter of the motion.
        duration_s: Length in seconds.
        fps_hz: Frame rate, Hz.
        kinds: Kinds to draw from (uniformly); all of :data:`PROCEDURAL_KINDS` when None.

    Raises:
        ValueError: An unknown or empty ``kinds``, or an argument out of range.
    """
    pool = PROCEDURAL_KINDS if kinds is None else tuple(kinds)
    if not pool:
        raise ValueError(f"kinds must name at least one of {', '.join(PROCEDURAL_KINDS)}, got none")
    bad = [k for k in pool if k not in PROCEDURAL_KINDS]
    if bad:
        raise ValueError(
            f"unknown procedural motion kinds {bad}; expected some of {', '.join(PROCEDURAL_KINDS)}"
        )
    _check_args(pool[0], seed, duration_s, fps_hz, None, None)
    # A stream separate from the one generate_motion uses, so the kind does not correlate with the body.
    kind = pool[int(np.random.default_rng([int(seed), 0x6B696E64]).integers(len(pool)))]
    return generate_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)


def kinds_for_skeleton(skeleton: str) -> tuple[str, ...]:
    """Procedural motion kinds available on a registered topology (empty when none).

    Human topologies (CMU-31 and the keypoint sets derived from it) take :data:`PROCEDURAL_KINDS`,
    ``hand21`` takes :data:`HAND_KINDS`, ``quadruped36`` :data:`QUADRUPED_KINDS` and ``monkey13``
    :data:`MONKEY_KINDS`.
    """
    from gttdata.skeletons import derivable_from_cmu31, get_skeleton

    name = get_skeleton(skeleton).name
    if name in derivable_from_cmu31():
        return PROCEDURAL_KINDS
    return {"hand21": HAND_KINDS, "quadruped36": QUADRUPED_KINDS, "monkey13": MONKEY_KINDS}.get(name, ())


def generate_skeleton_motion(
    skeleton: str, kind: str, *, seed: int, duration_s: float = 10.0, fps_hz: float = 120.0
) -> Motion:
    """One procedural motion on any topology that has a procedural source.

    Human keypoint sets are the CMU-31 motion ``generate_motion(kind, seed=seed, ...)`` mapped by
    :func:`gttdata.skeletons.derive_from_cmu31`, so ``coco17`` seed 5 is the same movement as
    ``cmu31`` seed 5.

    Args:
        skeleton: A registered topology name with procedural kinds (:func:`kinds_for_skeleton`).
        kind: One of ``kinds_for_skeleton(skeleton)``.
        seed: Non-negative seed.
        duration_s: Length in seconds.
        fps_hz: Frame rate, Hz.

    Raises:
        ValueError: No procedural source for the topology, or a kind it does not have.
    """
    from gttdata.skeletons import derive_from_cmu31, get_skeleton

    name = get_skeleton(skeleton).name
    kinds = kinds_for_skeleton(name)
    if kind not in kinds:
        raise ValueError(
            f"skeleton {name!r}: expected a procedural kind among {', '.join(kinds) or '(none)'}, found {kind!r}"
        )
    if name == "hand21":
        return generate_hand_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
    if name == "quadruped36":
        return generate_quadruped_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
    if name == "monkey13":
        return generate_monkey_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
    motion = generate_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
    return motion if name == "cmu31" else derive_from_cmu31(motion, name)
