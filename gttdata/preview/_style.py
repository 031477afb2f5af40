"""Shared preview palette: which side of the body each joint is on, and its colour."""

from __future__ import annotations

import numpy as np

from gttdata.skeleton import Skeleton

__all__ = [
    "CENTRE",
    "LEFT",
    "RIGHT",
    "SIDE_RGB",
    "SUBJECT_RGB",
    "bone_rgb",
    "bone_sides",
    "joint_rgb",
    "joint_sides",
    "joint_subjects",
    "rgb_bgr_u8",
    "side_bgr_u8",
]

CENTRE, LEFT, RIGHT = 0, 1, 2

#: Colour of each side as float RGB in [0, 1]: midline light grey, left blue, right orange-red.
SIDE_RGB: tuple[tuple[float, float, float], ...] = (
    (0.85, 0.85, 0.85),
    (0.15, 0.55, 1.00),
    (1.00, 0.35, 0.15),
)


#: Colours of subject s in multi-subject captures, one hue per subject, as (midline, left, right) float RGB:
#: left is the lighter and right the darker shade of the subject's hue.
SUBJECT_RGB: tuple[tuple[tuple[float, float, float], ...], ...] = (
    ((0.55, 0.70, 0.95), (0.55, 0.80, 1.00), (0.10, 0.40, 0.95)),  # blue
    ((1.00, 0.70, 0.40), (1.00, 0.80, 0.45), (0.90, 0.40, 0.05)),  # orange
    ((0.55, 0.90, 0.55), (0.65, 1.00, 0.60), (0.15, 0.65, 0.20)),  # green
    ((0.85, 0.60, 0.95), (0.92, 0.75, 1.00), (0.60, 0.25, 0.85)),  # purple
)


def joint_subjects(skeleton: Skeleton) -> np.ndarray:
    """Subject of each joint of a stacked multi-subject skeleton, shape ``(J,)`` int64.

    ``merge_subjects`` names subject s's joints with the prefix ``"a_"``, ``"b_"``, ...; a skeleton whose
    names do not all carry such a prefix, or carry only one, is a single subject (all zeros).
    """
    names = skeleton.joint_names
    if not names or not all(len(n) > 2 and n[1] == "_" and "a" <= n[0] <= "z" for n in names):
        return np.zeros(len(names), dtype=np.int64)
    letters = np.array([ord(n[0]) - ord("a") for n in names], dtype=np.int64)
    return letters if len(np.unique(letters)) > 1 else np.zeros(len(names), dtype=np.int64)


def joint_rgb(skeleton: Skeleton) -> np.ndarray:
    """Float RGB colour of each joint, shape ``(J, 3)``.

    One subject: by body side (:data:`SIDE_RGB`). Several stacked subjects: one hue per subject
    (:data:`SUBJECT_RGB`), lighter on the left and darker on the right.
    """
    sides = joint_sides(skeleton)
    subjects = joint_subjects(skeleton)
    if not subjects.any():
        return np.array(SIDE_RGB, dtype=np.float64)[sides]
    pal = np.array(SUBJECT_RGB, dtype=np.float64)
    return pal[subjects % len(pal), sides]


def bone_rgb(skeleton: Skeleton) -> np.ndarray:
    """Float RGB colour of each drawn limb, shape ``(L, 3)``.

    Float RGB colour of each drawn limb of ``skeleton.limbs``, shape ``(L, 3)``: the colour of its side
    (:func:`bone_sides`) in its subject's palette, as :func:`joint_rgb`.
    """
    limbs = skeleton.limbs
    if not len(limbs):
        return np.zeros((0, 3))
    sides = bone_sides(skeleton)
    subjects = joint_subjects(skeleton)
    if not subjects.any():
        return np.array(SIDE_RGB, dtype=np.float64)[sides]
    pal = np.array(SUBJECT_RGB, dtype=np.float64)
    return pal[subjects[limbs[:, 0]] % len(pal), sides]


def rgb_bgr_u8(rgb) -> tuple[int, int, int]:
    """OpenCV BGR colour (0-255 ints) of a float RGB colour."""
    r, g, b = (float(c) for c in rgb)
    return int(round(b * 255)), int(round(g * 255)), int(round(r * 255))


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
    return rgb_bgr_u8(SIDE_RGB[int(side)])
