"""Capture-level augmentations F^GR (global rotation) and F^LR (per-image camera perturbation)."""

from __future__ import annotations

import numpy as np

from gttdata.augment.registry import register_augmentation
from gttdata.capture.occlusion import visible_in_camera
from gttdata.capture.sample import CaptureSample
from gttdata.capture.simulate import project_images

__all__ = ["axis_angle_matrix", "camera_perturbation", "global_rotation"]


def axis_angle_matrix(rotvec: np.ndarray) -> np.ndarray:
    """Rotation matrices from rotation vectors (Rodrigues).

    Args:
        rotvec: Axis times angle in radians, shape ``(..., 3)``.

    Returns:
        Rotations, shape ``(..., 3, 3)``.
    """
    w = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    k = w / np.where(theta[..., 0] > 0, theta[..., 0], 1.0)
    Kx = np.zeros(w.shape[:-1] + (3, 3))
    Kx[..., 0, 1], Kx[..., 0, 2], Kx[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    Kx = Kx - np.swapaxes(Kx, -1, -2)
    return np.eye(3) + np.sin(theta) * Kx + (1.0 - np.cos(theta)) * (Kx @ Kx)


def _variant(sample: CaptureSample, name: str, from_orig: np.ndarray, info: dict, **changes) -> CaptureSample:
    meta = dict(sample.meta)
    meta["variant_from_orig"] = np.asarray(from_orig, dtype=np.float64).tolist()
    meta["augment"] = {"name": name, **info}
    return sample.replace(variant=name, meta=meta, **changes)


@register_augmentation(
    "global_rotation", level="capture", choices={"axis": ("z", "so3")}, ranges={"max_angle_deg": (0, 180)}
)
def global_rotation(
    sample: CaptureSample, rng: np.random.Generator, *, axis: str = "z", max_angle_deg: float = 180.0
) -> CaptureSample:
    """F^GR: rotate the structure and every camera together about the world origin.

    The 2-D observations are unchanged (that is the point: the same images must give the rotated
    3-D answer). ``meta["variant_from_orig"]`` is the 4x4 rotation ``T`` with ``points3d = T . orig``.

    Args:
        sample: The capture.
        rng: Random generator.
        axis: ``z`` (about the vertical, keeps the floor) or ``so3`` (random axis).
        max_angle_deg: Angle drawn uniformly in ``[-max, max]`` degrees.
    """
    angle = np.deg2rad(rng.uniform(-max_angle_deg, max_angle_deg))
    if axis == "z":
        u = np.array([0.0, 0.0, 1.0])
    elif axis == "so3":
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
    else:
        raise ValueError(f"global_rotation: axis must be 'z' or 'so3', got {axis!r}")
    T = np.eye(4)
    T[:3, :3] = axis_angle_matrix(angle * u)
    # X' = R X and C' = R C keep every X_cam: cam_from_world' = cam_from_world . T^-1.
    cam_from_world = sample.cam_from_world @ np.linalg.inv(T)
    info = {"axis": u.tolist(), "angle_deg": float(np.rad2deg(angle))}
    return _variant(
        sample,
        "global_rotation",
        T,
        info,
        points3d=sample.points3d @ T[:3, :3].T,
        cam_from_world=cam_from_world,
    )


@register_augmentation(
    "camera_perturbation", level="capture", ranges={"rot_deg": (0, 45), "trans_m": (0, 10)}
)
def camera_perturbation(
    sample: CaptureSample, rng: np.random.Generator, *, rot_deg: float = 2.0, trans_m: float = 0.05
) -> CaptureSample:
    """F^LR: move each image's camera a little, then re-image the unchanged ground truth.

    Each image's camera turns about its centre by a rotation vector ``~ N(0, rot_deg^2 I)`` and its
    centre moves by ``~ N(0, trans_m^2 I)``. The ground truth is re-projected; each observed joint keeps
    its original detection error (noisy - clean), so noise, outliers and random drops stay consistent;
    joints that leave the image or go behind the camera become missing.
    ``meta["variant_from_orig"]`` is the identity.

    Args:
        sample: The capture.
        rng: Random generator.
        rot_deg: Std of each rotation-vector component, degrees.
        trans_m: Std of each centre displacement component, metres.
    """
    n = sample.n_images
    dR = axis_angle_matrix(rng.normal(0.0, np.deg2rad(rot_deg), size=(n, 3)))
    dC = rng.normal(0.0, trans_m, size=(n, 3))
    R = sample.cam_from_world[:, :3, :3]
    C = -np.einsum("nji,nj->ni", R, sample.cam_from_world[:, :3, 3]) + dC
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = dR @ R
    T[:, :3, 3] = -np.einsum("nij,nj->ni", T[:, :3, :3], C)
    gt_px, depth = project_images(sample.points3d, sample.K, T)
    error = np.where(sample.visible[..., None], sample.keypoints_px - sample.keypoints_gt_px, 0.0)
    visible = sample.visible & visible_in_camera(gt_px, depth, sample.image_size[sample.cam_id])
    noisy = np.where(visible[..., None], gt_px + error, np.nan)
    return _variant(
        sample,
        "camera_perturbation",
        np.eye(4),
        {"rot_deg": rot_deg, "trans_m": trans_m},
        cam_from_world=T,
        keypoints_gt_px=gt_px.astype(np.float32),
        keypoints_px=noisy.astype(np.float32),
        visible=visible,
    )
