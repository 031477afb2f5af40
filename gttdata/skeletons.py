"""Named skeleton families: detector keypoint sets, hands, animals, and the maps from CMU-31 mocap.

Every topology the generator can simulate is registered here by name::

    >>> from gttdata.skeletons import available_skeletons, get_skeleton
    >>> get_skeleton("coco17").n_joints
    17
    >>> "halpe26" in available_skeletons()
    True

Families group topologies that share a body plan (``human``, ``hand``, ``quadruped``, ``markers``);
cross-domain experiments hold out whole families or single topologies.

Detector keypoint sets keep their tools' canonical joint order (COCO-17 as in the COCO keypoint
challenge and MMPose, H36M-17 as in Human3.6M's 17-joint subset, Body-25 as in OpenPose, Halpe-26
as in AlphaPose, hand-21 as in OpenPose/MMPose). Their trees are spanning trees of the tools' limb
lists; limbs that would close a cycle (COCO's shoulder-shoulder, hip-hip and eye-eye links) are
kept as :attr:`~gttdata.skeleton.Skeleton.extra_bones` for drawing.

The human keypoint sets are derived from CMU-31 mocap by :func:`derive_from_cmu31`. Most joints are
CMU joints (CMU-31 positions are at the start of each bone, as in the CMU BVH files: ``lfemur`` is
the hip joint, ``ltibia`` the knee, ``lfoot`` the ankle, ``ltoes`` the ball of the foot,
``lhumerus`` the shoulder, ``lradius`` the elbow, ``lwrist`` the wrist, ``head`` the base of the
skull). The face points (nose, eyes, ears), the top of the head and the foot tips (big toe, small
toe, heel) have no CMU joint: they are **virtual joints placed by fixed offsets in a body frame**
(see :data:`VIRTUAL_RULES`). They are approximations: CMU-31 does not record the head's yaw relative
to the shoulders nor the foot's roll, so a turned head puts the nose where the chest faces, and a
detector's keypoints on real images will differ from them by a few centimetres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gttdata.mocap.motion import Motion
from gttdata.skeleton import CMU31_JOINTS, Skeleton, cmu31

__all__ = [
    "CMU31_DERIVATIONS",
    "FAMILIES",
    "SkeletonSpec",
    "VIRTUAL_RULES",
    "available_skeletons",
    "base_skeleton_name",
    "derivable_from_cmu31",
    "derive_from_cmu31",
    "derive_positions",
    "get_skeleton",
    "register_skeleton",
    "skeleton_family",
    "skeleton_spec",
]

#: Body-plan families, in the order the docs list them.
FAMILIES: tuple[str, ...] = ("human", "hand", "quadruped", "primate", "markers")


def _tree(name: str, joints: tuple[str, ...], edges: dict[str, str | None], extra=(), mirror=()) -> Skeleton:
    """Build a skeleton from ``{child: parent or None}`` by name, keeping ``joints``' order."""
    idx = {n: i for i, n in enumerate(joints)}
    parents = tuple(-1 if (p := edges[n]) is None else idx[p] for n in joints)
    return Skeleton(
        name=name,
        joint_names=joints,
        parents=parents,
        mirror=mirror,
        extra_bones=tuple((idx[a], idx[b]) for a, b in extra),
    )


# ---------------------------------------------------------------------------------------------------
# Detector keypoint sets
# ---------------------------------------------------------------------------------------------------

COCO17_JOINTS: tuple[str, ...] = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
)  # fmt: skip


def coco17() -> Skeleton:
    """COCO-17 keypoints (COCO keypoint challenge, MMPose ``coco``), rooted at the nose."""
    e: dict[str, str | None] = {"nose": None}
    for s in ("left", "right"):
        e |= {
            f"{s}_eye": "nose", f"{s}_ear": f"{s}_eye", f"{s}_shoulder": f"{s}_ear",
            f"{s}_elbow": f"{s}_shoulder", f"{s}_wrist": f"{s}_elbow", f"{s}_hip": f"{s}_shoulder",
            f"{s}_knee": f"{s}_hip", f"{s}_ankle": f"{s}_knee",
        }  # fmt: skip
    extra = (("left_eye", "right_eye"), ("left_shoulder", "right_shoulder"), ("left_hip", "right_hip"))
    return _tree("coco17", COCO17_JOINTS, e, extra)


H36M17_JOINTS: tuple[str, ...] = (
    "pelvis", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
    "spine", "thorax", "neck_nose", "head_top",
    "left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow", "right_wrist",
)  # fmt: skip


def h36m17() -> Skeleton:
    """Human3.6M 17-joint subset (VideoPose3D / MMPose ``h36m`` order), rooted at the pelvis.

    Joint 9 (``neck_nose``) is Human3.6M's "Neck/Nose" marker, which sits in front of the upper neck
    at about chin height; joint 10 (``head_top``) is the top of the head.
    """
    e = {"pelvis": None, "spine": "pelvis", "thorax": "spine", "neck_nose": "thorax", "head_top": "neck_nose"}
    for s in ("left", "right"):
        e |= {
            f"{s}_hip": "pelvis", f"{s}_knee": f"{s}_hip", f"{s}_ankle": f"{s}_knee",
            f"{s}_shoulder": "thorax", f"{s}_elbow": f"{s}_shoulder", f"{s}_wrist": f"{s}_elbow",
        }  # fmt: skip
    return _tree("h36m17", H36M17_JOINTS, e)


BODY25_JOINTS: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "MidHip", "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle",
    "REye", "LEye", "REar", "LEar", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
)  # fmt: skip


def body25() -> Skeleton:
    """OpenPose BODY_25 keypoints (OpenPose names and order); the tree is OpenPose's 24 limbs."""
    e = {"Nose": None, "Neck": "Nose", "MidHip": "Neck"}
    for s in ("L", "R"):
        e |= {
            f"{s}Shoulder": "Neck", f"{s}Elbow": f"{s}Shoulder", f"{s}Wrist": f"{s}Elbow",
            f"{s}Hip": "MidHip", f"{s}Knee": f"{s}Hip", f"{s}Ankle": f"{s}Knee",
            f"{s}Eye": "Nose", f"{s}Ear": f"{s}Eye",
            f"{s}BigToe": f"{s}Ankle", f"{s}SmallToe": f"{s}BigToe", f"{s}Heel": f"{s}Ankle",
        }  # fmt: skip
    return _tree("body25", BODY25_JOINTS, e)


HALPE26_JOINTS: tuple[str, ...] = COCO17_JOINTS + (
    "head", "neck", "hip", "left_big_toe", "right_big_toe", "left_small_toe", "right_small_toe",
    "left_heel", "right_heel",
)  # fmt: skip


def halpe26() -> Skeleton:
    """Halpe-26 keypoints (AlphaPose ``halpe_26`` order), rooted at the mid-hip ``hip``.

    AlphaPose's limb list leaves the face (nose, eyes, ears) unconnected to the body; the tree
    links the nose to ``head`` (the top of the head) so that every joint has a bone.
    """
    e = {"hip": None, "neck": "hip", "head": "neck", "nose": "head"}
    for s in ("left", "right"):
        e |= {
            f"{s}_eye": "nose", f"{s}_ear": f"{s}_eye",
            f"{s}_shoulder": "neck", f"{s}_elbow": f"{s}_shoulder", f"{s}_wrist": f"{s}_elbow",
            f"{s}_hip": "hip", f"{s}_knee": f"{s}_hip", f"{s}_ankle": f"{s}_knee",
            f"{s}_heel": f"{s}_ankle", f"{s}_big_toe": f"{s}_heel", f"{s}_small_toe": f"{s}_heel",
        }  # fmt: skip
    return _tree("halpe26", HALPE26_JOINTS, e)


HAND21_JOINTS: tuple[str, ...] = ("wrist",) + tuple(
    f"{finger}{k}" for finger in ("thumb", "index", "middle", "ring", "pinky") for k in range(1, 5)
)


def hand21() -> Skeleton:
    """Hand-21 keypoints (OpenPose / MMPose hand order): the wrist, then 4 joints per finger.

    Per finger, 1..4 run from the base to the tip: thumb CMC, MCP, IP, tip; other fingers MCP, PIP,
    DIP, tip. One hand has no left/right pairs, so the mirror map is the identity.
    """
    e: dict[str, str | None] = {"wrist": None}
    for f in ("thumb", "index", "middle", "ring", "pinky"):
        e |= {f"{f}1": "wrist", f"{f}2": f"{f}1", f"{f}3": f"{f}2", f"{f}4": f"{f}3"}
    return _tree("hand21", HAND21_JOINTS, e, mirror=tuple(range(21)))


# ---------------------------------------------------------------------------------------------------
# Animals
# ---------------------------------------------------------------------------------------------------

_Q_SPINE = ("pelvis", "spine1", "spine2", "spine3", "withers")
_Q_NECK = ("neck1", "neck2", "head", "nose")
_Q_TAIL = tuple(f"tail{k}" for k in range(1, 6))
_Q_FRONT = ("shoulder", "elbow", "front_wrist", "front_paw", "front_toe")
_Q_HIND = ("hip", "knee", "hock", "hind_paw", "hind_toe")

QUADRUPED36_JOINTS: tuple[str, ...] = (
    _Q_SPINE
    + _Q_NECK
    + ("left_ear", "right_ear")
    + _Q_TAIL
    + tuple(f"{s}_{n}" for s in ("left", "right") for n in _Q_FRONT)
    + tuple(f"{s}_{n}" for s in ("left", "right") for n in _Q_HIND)
)


def quadruped36() -> Skeleton:
    """A four-legged animal (dog-like), 36 joints, rooted at the pelvis.

    Spine ``pelvis`` -> ``withers`` (5), neck and head ``neck1``, ``neck2``, ``head``, ``nose`` (4),
    two ears, a tail of 5 joints from the pelvis, and per leg 5 joints: front ``shoulder``, ``elbow``,
    ``front_wrist`` (carpus), ``front_paw``, ``front_toe`` from the withers; hind ``hip``, ``knee``
    (stifle), ``hock``, ``hind_paw``, ``hind_toe`` from the pelvis.
    """
    chain = _Q_SPINE + _Q_NECK
    e: dict[str, str | None] = {"pelvis": None}
    e |= {c: p for p, c in zip(chain[:-1], chain[1:], strict=True)}
    e |= {"left_ear": "head", "right_ear": "head", "tail1": "pelvis"}
    e |= {c: p for p, c in zip(_Q_TAIL[:-1], _Q_TAIL[1:], strict=True)}
    for s in ("left", "right"):
        for names, base in ((_Q_FRONT, "withers"), (_Q_HIND, "pelvis")):
            e[f"{s}_{names[0]}"] = base
            e |= {f"{s}_{c}": f"{s}_{p}" for p, c in zip(names[:-1], names[1:], strict=True)}
    return _tree("quadruped36", QUADRUPED36_JOINTS, e)


MONKEY13_JOINTS: tuple[str, ...] = (
    "nose", "head", "neck", "right_shoulder", "right_hand", "left_shoulder", "left_hand",
    "hip", "right_knee", "right_foot", "left_knee", "left_foot", "tail",
)  # fmt: skip


def monkey13() -> Skeleton:
    """A monkey as markerless primate studios annotate it (OpenMonkeyStudio-style), 13 joints, rooted at the nose.

    Head ``nose`` -> ``head`` -> ``neck``; from the neck each ``shoulder`` -> ``hand`` (no elbow) and the
    ``hip``; from the hip each ``knee`` -> ``foot`` and the ``tail`` (its tip).
    """
    e: dict[str, str | None] = {"nose": None, "head": "nose", "neck": "head", "hip": "neck", "tail": "hip"}
    for s in ("left", "right"):
        e |= {
            f"{s}_shoulder": "neck",
            f"{s}_hand": f"{s}_shoulder",
            f"{s}_knee": "hip",
            f"{s}_foot": f"{s}_knee",
        }
    return _tree("monkey13", MONKEY13_JOINTS, e)


# ---------------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SkeletonSpec:
    """A registered topology.

    Args:
        name: Registry name (lower case, e.g. ``"coco17"``).
        family: Body-plan family, one of :data:`FAMILIES`.
        build: Returns the :class:`Skeleton`.
        source: How motions on this topology are made (for docs and ``gttdata skeletons``).
    """

    name: str
    family: str
    build: Callable[[], Skeleton]
    source: str


_REGISTRY: dict[str, SkeletonSpec] = {}


def _key(name: str) -> str:
    return name.lower().replace("-", "").replace("_", "")


def register_skeleton(name: str, family: str, build: Callable[[], Skeleton], source: str) -> None:
    """Register (or replace) a topology under ``name``; lookups ignore case, ``-`` and ``_``."""
    if family not in FAMILIES:
        raise ValueError(f"skeleton {name!r}: family must be one of {', '.join(FAMILIES)}, got {family!r}")
    _REGISTRY[_key(name)] = SkeletonSpec(name, family, build, source)


def available_skeletons(family: str | None = None) -> tuple[str, ...]:
    """Registered topology names (optionally of one family), sorted."""
    return tuple(sorted(s.name for s in _REGISTRY.values() if family is None or s.family == family))


def skeleton_spec(name: str) -> SkeletonSpec:
    """The registry entry for ``name``; raises KeyError listing the known names."""
    try:
        return _REGISTRY[_key(name)]
    except KeyError:
        raise KeyError(
            f"unknown skeleton {name!r}; expected one of {', '.join(available_skeletons())}"
        ) from None


def get_skeleton(name: str) -> Skeleton:
    """The registered topology called ``name`` (e.g. ``"coco17"``, ``"COCO-17"``)."""
    return skeleton_spec(name).build()


def base_skeleton_name(name: str) -> str:
    """The registered topology an augmented one came from: ``"coco17+subset"`` -> ``"coco17"``."""
    return name.split("+", 1)[0]


def skeleton_family(name: str) -> str | None:
    """Family of a topology name (augmented names count as their base), or None when not registered.

    A mocap file's own skeleton (e.g. C3D markers) is not registered: None.
    """
    spec = _REGISTRY.get(_key(base_skeleton_name(name)))
    return None if spec is None else spec.family


# ---------------------------------------------------------------------------------------------------
# CMU-31 -> keypoint-set derivation
# ---------------------------------------------------------------------------------------------------

_J = {n: i for i, n in enumerate(CMU31_JOINTS)}

# Reference lengths of the CMU subject the offsets below were measured on (see
# gttdata.mocap.procedural._body): head joint above the upper neck, and ankle to ball of the foot.
_REF_HEAD_M = 0.100
_REF_FOOT_M = 0.137

#: Virtual joint rules: offsets in metres for the reference subject, in a body frame, scaled per
#: subject by its head segment (``upperneck`` -> ``head``) or foot segment (``lfoot`` -> ``ltoes``)
#: relative to the reference. Head frame: origin the CMU ``head`` joint (base of the skull), ``up``
#: along ``upperneck -> head``, ``left`` along ``rhumerus -> lhumerus`` made orthogonal to ``up``,
#: ``fwd = left x up``. Foot frame: origin the ankle (``lfoot``/``rfoot``), ``up`` along
#: ``ankle -> knee``, ``fwd`` the ``ankle -> toes`` direction made orthogonal to ``up``, ``out``
#: the side away from the body.
VIRTUAL_RULES: dict[str, str] = {
    "nose": "head + 0.04 up + 0.11 fwd",
    "eye": "head + 0.075 up + 0.085 fwd ± 0.032 left (+ for the left eye)",
    "ear": "head + 0.05 up ± 0.075 left (+ for the left ear)",
    "head_top": "head + 0.17 up",
    "neck_nose": "head - 0.01 up + 0.08 fwd (Human3.6M's Neck/Nose marker, about the chin)",
    "heel": "ankle - 0.05 fwd - 0.045 up",
    "big_toe": "ball + 0.055 fwd - 0.02 out - 0.01 up (ball = lfoot/rfoot's toes joint)",
    "small_toe": "ball + 0.035 fwd + 0.035 out - 0.01 up",
}

_HEAD_OFFSETS = {  # (up, fwd, side) in metres at reference scale; side is +left for left joints
    "nose": (0.04, 0.11, 0.0),
    "eye": (0.075, 0.085, 0.032),
    "ear": (0.05, 0.0, 0.075),
    "head_top": (0.17, 0.0, 0.0),
    "neck_nose": (-0.01, 0.08, 0.0),
}
_FOOT_OFFSETS = {  # (origin, up, fwd, out) at reference scale
    "heel": ("ankle", -0.045, -0.05, 0.0),
    "big_toe": ("ball", -0.01, 0.055, -0.02),
    "small_toe": ("ball", -0.01, 0.035, 0.035),
}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _head_point(p: np.ndarray, rule: str, side: float) -> np.ndarray:
    """Virtual head point for ``p`` of shape ``(..., 31, 3)``; ``side`` +1 left, -1 right, 0 midline."""
    head, neck = p[..., _J["head"], :], p[..., _J["upperneck"], :]
    seg = head - neck
    scale = np.clip(np.linalg.norm(seg, axis=-1, keepdims=True) / _REF_HEAD_M, 0.6, 1.6)
    up = _unit(seg)
    left = p[..., _J["lhumerus"], :] - p[..., _J["rhumerus"], :]
    left = _unit(left - np.sum(left * up, axis=-1, keepdims=True) * up)
    fwd = np.cross(left, up)
    du, df, ds = _HEAD_OFFSETS[rule]
    return head + scale * (du * up + df * fwd + side * ds * left)


def _foot_point(p: np.ndarray, rule: str, side: str) -> np.ndarray:
    """Virtual foot point for ``p`` of shape ``(..., 31, 3)``; ``side`` is ``"l"`` or ``"r"``."""
    ankle, ball, knee = (p[..., _J[side + n], :] for n in ("foot", "toes", "tibia"))
    seg = ball - ankle
    scale = np.clip(np.linalg.norm(seg, axis=-1, keepdims=True) / _REF_FOOT_M, 0.6, 1.6)
    up = _unit(knee - ankle)
    fwd = _unit(seg - np.sum(seg * up, axis=-1, keepdims=True) * up)
    out = np.cross(up, fwd) * (1.0 if side == "l" else -1.0)  # up x fwd points left
    origin, du, df, do = _FOOT_OFFSETS[rule]
    base = ankle if origin == "ankle" else ball
    return base + scale * (du * up + df * fwd + do * out)


def _joint(name: str) -> tuple:
    return ("joint", name)


def _mean(*names: str) -> tuple:
    return ("mean", names)


def _head(rule: str, side: float = 0.0) -> tuple:
    return ("head", rule, side)


def _foot(rule: str, side: str) -> tuple:
    return ("foot", rule, side)


def _human_map(target: str) -> dict[str, tuple]:
    lr = {"left": "l", "right": "r"}
    sign = {"left": 1.0, "right": -1.0}
    m: dict[str, tuple] = {}
    if target in ("coco17", "halpe26"):
        m["nose"] = _head("nose")
        for s, c in lr.items():
            m |= {
                f"{s}_eye": _head("eye", sign[s]), f"{s}_ear": _head("ear", sign[s]),
                f"{s}_shoulder": _joint(c + "humerus"), f"{s}_elbow": _joint(c + "radius"),
                f"{s}_wrist": _joint(c + "wrist"), f"{s}_hip": _joint(c + "femur"),
                f"{s}_knee": _joint(c + "tibia"), f"{s}_ankle": _joint(c + "foot"),
            }  # fmt: skip
    if target == "halpe26":
        m |= {
            "head": _head("head_top"),
            "neck": _mean("lhumerus", "rhumerus"),
            "hip": _mean("lfemur", "rfemur"),
        }
        for s, c in lr.items():
            m |= {
                f"{s}_big_toe": _foot("big_toe", c), f"{s}_small_toe": _foot("small_toe", c),
                f"{s}_heel": _foot("heel", c),
            }  # fmt: skip
    if target == "h36m17":
        m |= {
            "pelvis": _joint("root"), "spine": _joint("upperback"), "thorax": _joint("thorax"),
            "neck_nose": _head("neck_nose"), "head_top": _head("head_top"),
        }  # fmt: skip
        for s, c in lr.items():
            m |= {
                f"{s}_hip": _joint(c + "femur"), f"{s}_knee": _joint(c + "tibia"), f"{s}_ankle": _joint(c + "foot"),
                f"{s}_shoulder": _joint(c + "humerus"), f"{s}_elbow": _joint(c + "radius"),
                f"{s}_wrist": _joint(c + "wrist"),
            }  # fmt: skip
    if target == "body25":
        m |= {
            "Nose": _head("nose"),
            "Neck": _mean("lhumerus", "rhumerus"),
            "MidHip": _mean("lfemur", "rfemur"),
        }
        for s, c in (("L", "l"), ("R", "r")):
            sg = 1.0 if s == "L" else -1.0
            m |= {
                f"{s}Shoulder": _joint(c + "humerus"), f"{s}Elbow": _joint(c + "radius"),
                f"{s}Wrist": _joint(c + "wrist"), f"{s}Hip": _joint(c + "femur"),
                f"{s}Knee": _joint(c + "tibia"), f"{s}Ankle": _joint(c + "foot"),
                f"{s}Eye": _head("eye", sg), f"{s}Ear": _head("ear", sg),
                f"{s}BigToe": _foot("big_toe", c), f"{s}SmallToe": _foot("small_toe", c),
                f"{s}Heel": _foot("heel", c),
            }  # fmt: skip
    if target == "cmu31":
        m = {n: _joint(n) for n in CMU31_JOINTS}
    return m


def _describe(rule: tuple) -> str:
    kind = rule[0]
    if kind == "joint":
        return rule[1]
    if kind == "mean":
        return "mean(" + ", ".join(rule[1]) + ")"
    side = {1.0: "left ", -1.0: "right ", 0.0: ""}.get(rule[2], "") if kind == "head" else ""
    if kind == "foot":
        side = {"l": "left ", "r": "right "}[rule[2]]
    return f"virtual {side}{rule[1]}: {VIRTUAL_RULES[rule[1]]}"


_DERIVABLE = ("cmu31", "coco17", "h36m17", "body25", "halpe26")

#: Per target topology, each joint (canonical order) -> how it is computed from CMU-31: a CMU joint
#: name, ``mean(a, b)``, or ``virtual <rule>`` (see :data:`VIRTUAL_RULES`).
CMU31_DERIVATIONS: dict[str, dict[str, str]] = {
    t: {n: _describe(r) for n, r in _human_map(t).items()} for t in _DERIVABLE
}


def derivable_from_cmu31() -> tuple[str, ...]:
    """Topologies :func:`derive_from_cmu31` can produce."""
    return _DERIVABLE


def derive_positions(positions: np.ndarray, target: str) -> np.ndarray:
    """Keypoints of ``target`` computed from CMU-31 joint positions.

    Args:
        positions: CMU-31 joint positions in metres, shape ``(..., 31, 3)``, world z-up.
        target: A name in :func:`derivable_from_cmu31`.

    Returns:
        Positions of the target's joints in its canonical order, metres, shape ``(..., J, 3)``.
    """
    sk = get_skeleton(target)
    if sk.name not in _DERIVABLE:
        raise KeyError(
            f"skeleton {target!r} cannot be derived from CMU-31; expected one of {', '.join(_DERIVABLE)}"
        )
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim < 2 or p.shape[-2:] != (31, 3):
        raise ValueError(f"positions must have shape (..., 31, 3) (CMU-31), got {p.shape}")
    rules = _human_map(sk.name)
    out = np.empty(p.shape[:-2] + (sk.n_joints, 3))
    for j, name in enumerate(sk.joint_names):
        r = rules[name]
        if r[0] == "joint":
            out[..., j, :] = p[..., _J[r[1]], :]
        elif r[0] == "mean":
            out[..., j, :] = np.mean([p[..., _J[n], :] for n in r[1]], axis=0)
        elif r[0] == "head":
            out[..., j, :] = _head_point(p, r[1], r[2])
        else:
            out[..., j, :] = _foot_point(p, r[1], r[2])
    return out


def derive_from_cmu31(motion: Motion, target: str) -> Motion:
    """The same motion on another human topology (see the module docstring for the rules).

    Args:
        motion: A motion on the CMU-31 skeleton (``motion.skeleton.name == "cmu31"``).
        target: A name in :func:`derivable_from_cmu31`.

    Returns:
        A Motion on ``get_skeleton(target)`` with positions of shape ``(T, J, 3)``, metres.
    """
    if motion.skeleton.joint_names != CMU31_JOINTS:
        raise ValueError(
            f"motion {motion.name!r}: derive_from_cmu31 needs the CMU-31 skeleton, got "
            f"{motion.skeleton.name!r} with {motion.skeleton.n_joints} joints"
        )
    sk = get_skeleton(target)
    prov = dict(motion.provenance, derived_from="cmu31", derivation=sk.name)
    return Motion(derive_positions(motion.positions, sk.name), motion.fps_hz, sk, motion.name, prov)


_HUMAN_SOURCE = "CMU-31 mocap or procedural motion, via derive_from_cmu31 (virtual face and foot joints)"
register_skeleton("cmu31", "human", cmu31, "CMU-31 mocap (ASF/AMC, BVH) and the procedural human")
register_skeleton("coco17", "human", coco17, _HUMAN_SOURCE)
register_skeleton("h36m17", "human", h36m17, _HUMAN_SOURCE)
register_skeleton("body25", "human", body25, _HUMAN_SOURCE)
register_skeleton("halpe26", "human", halpe26, _HUMAN_SOURCE)
register_skeleton("hand21", "hand", hand21, "procedural hand (gttdata.mocap.procedural.generate_hand_motion)")
register_skeleton(
    "quadruped36",
    "quadruped",
    quadruped36,
    "procedural quadruped (gttdata.mocap.procedural.generate_quadruped_motion)",
)
register_skeleton(
    "monkey13", "primate", monkey13, "procedural monkey (gttdata.mocap.procedural.generate_monkey_motion)"
)


def _register_detector_sets() -> None:
    """Register the keypoint sets read from detector files only (:mod:`gttdata.skeletons_detectors`)."""
    from gttdata.skeletons_detectors import DETECTOR_SKELETONS

    for name, build in DETECTOR_SKELETONS.items():
        register_skeleton(
            name, "human", build, "detector files only (gttdata.skeletons_detectors); not simulated"
        )


_register_detector_sets()
