"""Motion-level augmentations applied before simulation: mirror, bone scaling and per-joint decorrelation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from gttdata.augment.registry import fires, register_augmentation
from gttdata.mocap.motion import Motion

__all__ = ["bone_scale", "decorrelate", "mirror"]


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


@register_augmentation(
    "decorrelate", level="motion", ranges={"prob": (0, 1), "max_angle_deg": (0, 180), "max_shift_m": (0, 10)}
)
def decorrelate(
    motion: Motion,
    rng: np.random.Generator,
    *,
    prob: float = 1.0,
    max_angle_deg: float = 180.0,
    max_shift_m: float = 0.5,
) -> Motion:
    """With probability ``prob``, apply an independent random rigid motion to each joint's trajectory.

    The paper's "decorrelated motion" control: every trajectory stays exactly as smooth as the original
    (a rigid transform of a curve), but the joints no longer move as one body, so a model trained on it
    can only learn temporal, not anatomical, structure. Joint j's trajectory is rotated about its own
    centroid by a uniform random axis and an angle in ``[0, max_angle_deg]``, then shifted by a uniform
    offset in ``[-max_shift_m, max_shift_m]`` per axis. The skeleton is kept (its bones are meaningless).

    Args:
        motion: The motion (world frame, metres).
        rng: Random generator; nothing is drawn when ``prob`` is 0, so recipes without this control
            keep their random streams (and shards) unchanged.
        prob: Probability of decorrelating this motion.
        max_angle_deg: Largest rotation angle per joint, degrees.
        max_shift_m: Largest translation per axis per joint, metres.
    """
    if not fires(rng, prob):
        return motion
    j = motion.skeleton.n_joints
    axes = rng.normal(size=(j, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.deg2rad(rng.uniform(0.0, max_angle_deg, size=j))
    shifts = rng.uniform(-max_shift_m, max_shift_m, size=(j, 3))
    R = Rotation.from_rotvec(axes * angles[:, None]).as_matrix()  # (J, 3, 3)
    centre = motion.positions.mean(axis=0)  # (J, 3)
    local = motion.positions - centre
    pos = np.einsum("jab,tjb->tja", R, local) + centre + shifts
    return replace(motion, positions=pos, name=f"{motion.name}+decorrelated")
