"""Motion-level augmentations applied before simulation: left/right mirror and bone scaling."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from gttdata.augment.registry import register_augmentation
from gttdata.mocap.motion import Motion

__all__ = ["bone_scale", "mirror"]


@register_augmentation("mirror", level="motion", ranges={"prob": (0, 1)})
def mirror(motion: Motion, rng: np.random.Generator, *, prob: float = 1.0) -> Motion:
    """With probability ``prob``, reflect the motion left/right (y -> -y, left and right joints swapped).

    Args:
        motion: The motion (world frame, metres).
        rng: Random generator (one draw, always taken so the stream stays aligned).
        prob: Mirror probability.
    """
    return motion.mirror(axis=1) if rng.random() < prob else motion


@register_augmentation("bone_scale", level="motion", ranges={"factor": (0.1, 10), "per_bone_std": (0, 1)})
def bone_scale(
    motion: Motion, rng: np.random.Generator, *, factor: float = 1.0, per_bone_std: float = 0.0
) -> Motion:
    """Rescale bone lengths (a taller / shorter subject), keeping the lowest point on the same height.

    Args:
        motion: The motion (world frame, metres).
        rng: Random generator (draws the per-bone factors; left and right bones share theirs).
        factor: Global bone-length factor.
        per_bone_std: Relative std of an extra per-bone factor.
    """
    j = motion.skeleton.n_joints
    f = np.full(j, float(factor))
    if per_bone_std > 0:
        g = rng.normal(1.0, per_bone_std, size=j)
        f *= np.clip(0.5 * (g + g[motion.skeleton.flip_index()]), 0.5, 1.5)
    if np.all(f == 1.0):
        return motion
    out = motion.scale_bones(f)
    # Scaling about the root would push the feet through the floor (or lift them): restore the lowest z.
    dz = motion.positions[..., 2].min() - out.positions[..., 2].min()
    pos = out.positions.copy()
    pos[..., 2] += dz
    return replace(out, positions=pos, name=f"{motion.name}+scale{factor:.3g}")
