"""Skeleton topologies: joint names, parents, bones and the left/right mirror map."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gttdata.errors import MotionFormatError

__all__ = ["Skeleton", "cmu31", "CMU31_JOINTS", "CMU31_BVH_ALIASES", "default_skeleton", "load_skeleton"]

#: CMU-31 joints in the bone order of the CMU ASF skeleton files (root first).
CMU31_JOINTS: tuple[str, ...] = (
    "root", "lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes",
    "rhipjoint", "rfemur", "rtibia", "rfoot", "rtoes",
    "lowerback", "upperback", "thorax", "lowerneck", "upperneck", "head",
    "lclavicle", "lhumerus", "lradius", "lwrist", "lhand", "lfingers", "lthumb",
    "rclavicle", "rhumerus", "rradius", "rwrist", "rhand", "rfingers", "rthumb",
)  # fmt: skip

_CMU31_PARENTS: tuple[int, ...] = (
    -1, 0, 1, 2, 3, 4,
    0, 6, 7, 8, 9,
    0, 11, 12, 13, 14, 15,
    13, 17, 18, 19, 20, 21, 20,
    13, 24, 25, 26, 27, 28, 27,
)  # fmt: skip

#: BVH names used by the CMU BVH conversions (cgspeed, e.g. 01_01.bvh), in the same order as CMU31_JOINTS.
CMU31_BVH_ALIASES: tuple[str, ...] = (
    "Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
    "RHipJoint", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase",
    "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftFingerBase", "LFingers", "LThumb",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightFingerBase", "RFingers", "RThumb",
)  # fmt: skip


def _mirror_by_name(names: tuple[str, ...]) -> tuple[int, ...]:
    """Mirror index of each joint, by swapping a left/right prefix in its name (self if none)."""
    swaps = (("left", "right"), ("Left", "Right"), ("l", "r"), ("L", "R"))
    index = {n: i for i, n in enumerate(names)}
    out = []
    for i, n in enumerate(names):
        j = i
        for a, b in swaps:
            for src, dst in ((a, b), (b, a)):
                if n.startswith(src) and dst + n[len(src) :] in index:
                    j = index[dst + n[len(src) :]]
                    break
            if j != i:
                break
        out.append(j)
    return tuple(out)


@dataclass(frozen=True)
class Skeleton:
    """A joint topology.

    Args:
        name: Topology name, e.g. ``"cmu31"``.
        joint_names: Joint names, length J.
        parents: Parent index of each joint (``-1`` for a root), length J. The parents form a forest
            (no cycles); a parent need not precede its child (detector keypoint sets keep their
            canonical order), :attr:`topological_order` lists parents first.
        mirror: Index of each joint's left/right counterpart (itself on the midline), length J.
            Derived from the names when empty.
        aliases: Alternative names per joint (e.g. BVH names), mapped to the joint index.
        extra_bones: Drawn links outside the parent tree, as ``(i, j)`` index pairs (e.g. COCO's
            shoulder-to-shoulder limb). Not used for bone-length edits.
    """

    name: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    mirror: tuple[int, ...] = ()
    aliases: dict[str, int] = field(default_factory=dict, compare=False, hash=False)
    extra_bones: tuple[tuple[int, int], ...] = ()

    def __post_init__(self) -> None:
        j = len(self.joint_names)
        if j == 0:
            raise ValueError(f"skeleton {self.name!r}: joint_names must be non-empty, got 0 joints")
        if len(self.parents) != j:
            raise ValueError(f"skeleton {self.name!r}: parents must have length {j}, got {len(self.parents)}")
        for i, p in enumerate(self.parents):
            if not (-1 <= p < j) or p == i:
                raise ValueError(
                    f"skeleton {self.name!r}: parent of joint {i} ({self.joint_names[i]}) must be -1 or another "
                    f"joint index in [0, {j}), got {p}"
                )
        for i in range(j):  # walk to the root; more than J steps means a cycle
            k, steps = i, 0
            while k >= 0 and steps <= j:
                k, steps = self.parents[k], steps + 1
            if k >= 0:
                raise ValueError(
                    f"skeleton {self.name!r}: parents form a cycle through joint {i} ({self.joint_names[i]})"
                )
        extra = tuple((int(a), int(b)) for a, b in self.extra_bones)
        if any(not (0 <= a < j and 0 <= b < j) or a == b for a, b in extra):
            raise ValueError(
                f"skeleton {self.name!r}: extra_bones must pair two distinct joints in [0, {j}), got {extra}"
            )
        object.__setattr__(self, "extra_bones", extra)
        if len(set(self.joint_names)) != j:
            raise ValueError(f"skeleton {self.name!r}: joint names must be unique")
        if not self.mirror:
            object.__setattr__(self, "mirror", _mirror_by_name(self.joint_names))
        if (
            len(self.mirror) != j
            or any(not 0 <= m < j for m in self.mirror)
            or any(self.mirror[self.mirror[i]] != i for i in range(j))
        ):
            raise ValueError(f"skeleton {self.name!r}: mirror must be an involution of length {j}")

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return len(self.joint_names)

    @property
    def bones(self) -> np.ndarray:
        """Bones as (child, parent) index pairs, shape ``(J - roots, 2)``, int64."""
        return np.array([(i, p) for i, p in enumerate(self.parents) if p >= 0], dtype=np.int64).reshape(-1, 2)

    @property
    def limbs(self) -> np.ndarray:
        """Every drawn link: the tree bones then :attr:`extra_bones`, shape ``(L, 2)``, int64."""
        extra = np.array(self.extra_bones, dtype=np.int64).reshape(-1, 2)
        return np.concatenate([self.bones, extra], axis=0)

    @property
    def topological_order(self) -> tuple[int, ...]:
        """Joint indices with every parent before its children (roots first, then by depth, stable)."""
        depth = []
        for i in range(self.n_joints):
            d, k = 0, self.parents[i]
            while k >= 0:
                d, k = d + 1, self.parents[k]
            depth.append(d)
        return tuple(sorted(range(self.n_joints), key=lambda i: (depth[i], i)))

    def flip_index(self) -> np.ndarray:
        """Permutation that swaps left and right joints, shape ``(J,)``."""
        return np.asarray(self.mirror, dtype=np.int64)

    def index(self, name: str) -> int:
        """Index of a joint by name or alias; raises KeyError naming the joint."""
        if name in self.joint_names:
            return self.joint_names.index(name)
        if name in self.aliases:
            return self.aliases[name]
        raise KeyError(f"skeleton {self.name!r} has no joint {name!r}")

    def to_dict(self) -> dict:
        """JSON-serialisable form (inverse of :meth:`from_dict`)."""
        d = {
            "name": self.name,
            "joint_names": list(self.joint_names),
            "parents": list(self.parents),
            "mirror": list(self.mirror),
        }
        if self.extra_bones:
            d["extra_bones"] = [list(b) for b in self.extra_bones]
        return d

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "<dict>") -> Skeleton:
        """Build from :meth:`to_dict` output; raises MotionFormatError naming the missing field."""
        for key in ("name", "joint_names", "parents"):
            if key not in d:
                raise MotionFormatError(f"{source}: skeleton field {key!r} is missing")
        try:
            return cls(
                name=str(d["name"]),
                joint_names=tuple(str(n) for n in d["joint_names"]),
                parents=tuple(int(p) for p in d["parents"]),
                mirror=tuple(int(m) for m in d.get("mirror", ())),
                extra_bones=tuple((int(a), int(b)) for a, b in d.get("extra_bones", ())),
            )
        except (TypeError, ValueError, OverflowError) as exc:
            raise MotionFormatError(f"{source}: invalid skeleton: {exc}") from exc


def cmu31() -> Skeleton:
    """The CMU 31-joint skeleton in ASF order, with the BVH name aliases.

    Example:
        >>> sk = cmu31()
        >>> sk.n_joints, sk.joint_names[sk.mirror[2]]
        (31, 'rfemur')
    """
    return Skeleton(
        name="cmu31",
        joint_names=CMU31_JOINTS,
        parents=_CMU31_PARENTS,
        aliases={a: i for i, a in enumerate(CMU31_BVH_ALIASES)},
    )


def load_skeleton(path: str | Path) -> Skeleton:
    """Read a topology from a JSON file holding ``name``, ``joint_names``, ``parents`` (and ``mirror``)."""
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise MotionFormatError(f"{path}: skeleton file not found") from exc
    except json.JSONDecodeError as exc:
        raise MotionFormatError(f"{path}: line {exc.lineno}: not valid JSON ({exc.msg})") from exc
    if not isinstance(d, dict):
        raise MotionFormatError(f"{path}: expected a JSON object, found {type(d).__name__}")
    return Skeleton.from_dict(d, source=str(path))


def default_skeleton(n_joints: int, prefix: str) -> Skeleton:
    """CMU-31 for 31 joints, else a star topology named ``<prefix><J>`` (joints ``j0..``, joint 0 the root).

    For captures whose files name no skeleton (imported layouts, synthetic test scenes).

    Example:
        >>> sk = default_skeleton(3, "imported")
        >>> sk.name, sk.parents
        ('imported3', (-1, 0, 0))
    """
    if n_joints == 31:
        return cmu31()
    return Skeleton(
        name=f"{prefix}{n_joints}",
        joint_names=tuple(f"j{i}" for i in range(n_joints)),
        parents=(-1,) + (0,) * (n_joints - 1),
    )
