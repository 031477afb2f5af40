"""Shared preview palette: which side of the body each joint is on, and its colour."""

from __future__ import annotations

import numpy as np

from gttdata.skeleton import Skeleton

__all__ = [
    "CENTRE",
    "LEFT",
    "RIGHT",
    "SIDE_RGB",
    "bone_sides",
    "joint_sides",
    "side_bgr_u8",
]

CENTRE, LEFT, RIGHT = 0, 1, 2

#: Colour of each side as float RGB in [0, 1]: midline light grey, left blue, right orange-red.
SIDE_RGB: tuple[tuple[float, float, float], ...] = (
    (0.85, 0.85, 0.85),
    (0.15, 0.55, 1.00),
    (1.00, 0.35, 0.15),
)


def _side_of_pair(a: str, b: str) -> int:
    """LEFT or RIGHT for name ``a`` whose mirror is named ``b``, from the first character where they differ."""
    k = next((i for i, (x, y) in enumerate(zip(a, b, strict=False)) if x != y), 0)
    ca = a[k : k + 1].lower()
    cb = b[k : k + 1].lower()
    if ca == "l" and cb == "r":
        return LEFT
    if ca == "r" and cb == "l":
        return RIGHT
    return 0


def joint_sides(skeleton: Skeleton) -> np.ndarray:
    """Body side of each joint from ``Skeleton.mirror`` and the names.

    A joint that is its own mirror is on the midline. For a mirrored pair, the names' first differing
    character decides (``l``/``L`` left, ``r``/``R`` right, so ``lfemur``, ``LeftUpLeg`` and ``a_lfemur``
    all work); pairs whose names do not say call the lower index left.

    Args:
        skeleton: Topology with J joints.

    Returns:
        Side per joint (CENTRE, LEFT or RIGHT), shape ``(J,)`` int64.
    """
    names = skeleton.joint_names
    out = np.full(skeleton.n_joints, CENTRE, dtype=np.int64)
    for i, m in enumerate(skeleton.mirror):
        if m == i:
            continue
        side = _side_of_pair(names[i], names[m])
        out[i] = side if side else (LEFT if i < m else RIGHT)
    return out


def bone_sides(skeleton: Skeleton) -> np.ndarray:
    """Side of each drawn limb of ``skeleton.limbs`` (tree bones, then extra bones), shape ``(L,)`` int64.

    A limb takes the side of its sided end; a limb joining a left and a right joint (COCO's
    shoulder-to-shoulder) is on the midline.
    """
    limbs = skeleton.limbs
    if not len(limbs):
        return np.zeros(0, dtype=np.int64)
    sides = joint_sides(skeleton)
    a, b = sides[limbs[:, 0]], sides[limbs[:, 1]]
    return np.where(a == b, a, np.where(a == CENTRE, b, np.where(b == CENTRE, a, CENTRE)))


def side_bgr_u8(side: int) -> tuple[int, int, int]:
    """OpenCV BGR colour (0-255 ints) of a side."""
    r, g, b = SIDE_RGB[int(side)]
    return int(round(b * 255)), int(round(g * 255)), int(round(r * 255))
