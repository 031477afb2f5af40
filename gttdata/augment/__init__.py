"""Registry of named augmentations: capture-level variants and motion-level edits."""

from __future__ import annotations

from gttdata.augment.capture import axis_angle_matrix, camera_perturbation, global_rotation
from gttdata.augment.motion import bone_scale, decorrelate, mirror
from gttdata.augment.registry import (
    AUGMENT_LEVELS,
    Augmentation,
    available_augmentations,
    get_augmentation,
    register_augmentation,
    validate_augmentation,
)
from gttdata.augment.topology import joint_subset, marker_offsets, merge_joints

__all__ = [
    "AUGMENT_LEVELS",
    "Augmentation",
    "available_augmentations",
    "axis_angle_matrix",
    "bone_scale",
    "camera_perturbation",
    "decorrelate",
    "get_augmentation",
    "global_rotation",
    "joint_subset",
    "marker_offsets",
    "merge_joints",
    "mirror",
    "register_augmentation",
    "validate_augmentation",
]
