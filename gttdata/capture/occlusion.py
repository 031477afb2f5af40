"""Missing observations: joints outside the image or behind the camera, random joint and image drops."""

from __future__ import annotations

import numpy as np

__all__ = ["drop_images", "drop_joints", "visible_in_camera"]


def visible_in_camera(pixels: np.ndarray, depth_m: np.ndarray, image_size: np.ndarray) -> np.ndarray:
    """Whether each projected joint can be seen: in front of the camera and inside its image.

    Args:
        pixels: Projected joints, pixels, shape ``(N, J, 2)``.
        depth_m: Depth along each image's optical axis, metres, shape ``(N, J)``.
        image_size: ``(width, height)`` of each image's camera, pixels, shape ``(N, 2)``.

    Returns:
        Mask of shape ``(N, J)`` bool.
    """
    w = np.asarray(image_size, dtype=np.float64)[:, None, 0]
    h = np.asarray(image_size, dtype=np.float64)[:, None, 1]
    u, v = pixels[..., 0], pixels[..., 1]
    with np.errstate(invalid="ignore"):
        inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    return inside & (depth_m > 0) & np.isfinite(u) & np.isfinite(v)


def drop_joints(shape: tuple[int, int], rng: np.random.Generator, *, rate: float) -> np.ndarray:
    """Random joint dropout (a detector's misses), independent per joint.

    Args:
        shape: ``(N, J)``.
        rng: Random generator.
        rate: Drop probability, in ``[0, 1]``.

    Returns:
        Kept mask of shape ``(N, J)`` bool (False = dropped).
    """
    return rng.random(shape) >= rate


def drop_images(
    cam_id: np.ndarray, rng: np.random.Generator, *, rate: float, min_per_camera: int = 2
) -> np.ndarray:
    """Random whole-image drops (lost frames), keeping at least ``min_per_camera`` images per camera.

    Args:
        cam_id: Camera of each image, shape ``(N,)``.
        rng: Random generator.
        rate: Drop probability per image, in ``[0, 1)``.
        min_per_camera: Images of a camera that are always kept (its first ones by index if needed).

    Returns:
        Kept mask of shape ``(N,)`` bool.
    """
    cam = np.asarray(cam_id)
    keep = np.asarray(rng.random(cam.shape[0]) >= rate)
    for v in np.unique(cam):
        idx = np.flatnonzero(cam == v)
        short = min(min_per_camera, idx.size) - int(keep[idx].sum())
        if short > 0:
            keep[idx[~keep[idx]][:short]] = True
    return keep
