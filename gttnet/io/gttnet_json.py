"""Importer of the GTT-Net JSON layout (per-image rays and centres, images in true time order)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from gttnet.errors import ImportFormatError
from gttnet.io._views import UNITS, ImportedCapture, default_skeleton

__all__ = ["read_gttnet_json", "rays_to_pixels"]

log = logging.getLogger(__name__)


def _array(path: Path, d: dict, key: str, ndim: int) -> np.ndarray:
    if key not in d:
        raise ImportFormatError(f"{path}: field '{key}': expected a numeric array, found no such key")
    try:
        a = np.asarray(d[key], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ImportFormatError(
            f"{path}: field '{key}': expected a rectangular numeric array, found {exc}"
        ) from exc
    if a.ndim != ndim:
        raise ImportFormatError(f"{path}: field '{key}': expected a {ndim}-D array, found shape {a.shape}")
    return a


def _vector(path: Path, d: dict, key: str) -> np.ndarray:
    """A numeric vector stored flat, as a row (1 x N) or as a column (N x 1)."""
    a = _array(path, d, key, np.ndim(d.get(key, [])) if np.ndim(d.get(key, [])) in (1, 2) else 1)
    if a.ndim == 2 and 1 not in a.shape:
        raise ImportFormatError(
            f"{path}: field '{key}': expected a vector of N values, found shape {a.shape}"
        )
    a = a.ravel()
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise ImportFormatError(
            f"{path}: field '{key}': expected N finite values, found {a.size} with NaN/inf or none"
        )
    return a


def _look_along(z: np.ndarray) -> np.ndarray:
    """A world→camera rotation whose optical axis (camera +z) is the unit vector ``z``."""
    up = np.eye(3)[int(np.argmin(np.abs(z)))]  # the world axis least aligned with z
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def rays_to_pixels(
    rays: np.ndarray, visible: np.ndarray, cam_id: np.ndarray, K: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels and a rotation per camera that reproduce given world rays exactly through ``K``.

    The layout stores rays but no rotations. Any rotation R turns a ray r into the pixel
    ``K R r`` (dehomogenised), and ``Observations.rays()`` maps it back to ``R^T K^-1 [u v 1]`` = r; so
    each camera gets the rotation whose optical axis is the mean of its observed rays, which keeps all
    of them in front of the camera.

    Args:
        rays: Unit world rays, shape ``(N, J, 3)``.
        visible: Observed mask, shape ``(N, J)``.
        cam_id: Camera of each image in ``[0, V)``, shape ``(N,)``.
        K: Intrinsics per camera, shape ``(V, 3, 3)``.

    Returns:
        ``(pixels (N, J, 2) NaN where missing, R (V, 3, 3) world→camera)``.

    Raises:
        ValueError: If a camera sees rays spread over more than a hemisphere.
    """
    V = K.shape[0]
    R = np.empty((V, 3, 3))
    for c in range(V):
        sel = visible & (cam_id == c)[:, None]
        m = rays[sel].sum(axis=0)
        R[c] = _look_along(m / np.linalg.norm(m)) if np.linalg.norm(m) > 0 else np.eye(3)
    cam_rays = np.einsum("nab,njb->nja", R[cam_id], rays)
    if np.any(cam_rays[..., 2][visible] <= 1e-6):
        raise ValueError("rays of one camera span more than a hemisphere; cannot express them as pixels")
    h = np.einsum("nab,njb->nja", K[cam_id], cam_rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        px = h[..., :2] / h[..., 2:3]
    px[~visible] = np.nan
    return px, R


def read_gttnet_json(path: str | Path, *, units: str = "inch") -> ImportedCapture:
    """Read a GTT-Net JSON file.

    Layout (REFERENCE.md): ``camID`` (N camera ids, any integers: cameras are numbered by sorted id),
    ``point3D`` (3P x N ground truth, joint-major rows), ``C`` (3 x N camera centres), ``K`` (3 x 3V,
    camera c in columns 3c..3c+2) and ``ray`` (3P x N unit world rays; an all-zero ray is a missing
    joint). Images are stored in true time order. Other keys (``A_GT``, ``rayDInd*``, ``X_init*``,
    ``t``) are ignored. Rays become pixels through ``K`` and a synthetic rotation per camera
    (:func:`rays_to_pixels`), so ``Observations.rays()`` returns the stored rays.

    Args:
        path: The ``.json`` file.
        units: Length unit of ``C`` and ``point3D`` (key of :data:`gttnet.io._views.UNITS`).

    Returns:
        The capture in file (time) order, with its time rank and ground truth.

    Raises:
        ImportFormatError: Naming the file, the field, what was expected and what was found.
    """
    path = Path(path)
    scale = UNITS[units]
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ImportFormatError(
            f"{path}: line {exc.lineno}: expected JSON, found invalid text ({exc.msg})"
        ) from exc
    except UnicodeDecodeError as exc:
        raise ImportFormatError(f"{path}: expected UTF-8 JSON text, found binary data") from exc
    if not isinstance(d, dict):
        raise ImportFormatError(f"{path}: expected a JSON object, found {type(d).__name__}")
    cam_raw = _vector(path, d, "camID")
    n = cam_raw.shape[0]
    ray = _array(path, d, "ray", 2)
    if ray.shape[1] != n or ray.shape[0] % 3 or ray.shape[0] == 0:
        raise ImportFormatError(
            f"{path}: field 'ray': expected shape (3P, N) with N = {n}, found {ray.shape}"
        )
    p = ray.shape[0] // 3
    X = _array(path, d, "point3D", 2)
    if X.shape != (3 * p, n):
        raise ImportFormatError(
            f"{path}: field 'point3D': expected shape (3P, N) = {(3 * p, n)}, found {X.shape}"
        )
    C = _array(path, d, "C", 2)
    if C.shape != (3, n):
        raise ImportFormatError(f"{path}: field 'C': expected shape (3, N) = {(3, n)}, found {C.shape}")
    ids, cam = np.unique(cam_raw, return_inverse=True)
    V = ids.shape[0]
    Kall = _array(path, d, "K", 2)
    if Kall.shape != (3, 3 * V):
        raise ImportFormatError(
            f"{path}: field 'K': expected shape (3, 3V) = {(3, 3 * V)} for {V} cameras, found {Kall.shape}"
        )
    K = Kall.reshape(3, V, 3).transpose(1, 0, 2)
    if np.any(np.abs(np.linalg.det(K)) < 1e-12):
        raise ImportFormatError(
            f"{path}: field 'K': expected non-singular 3 x 3 blocks, found a singular one"
        )
    rays = ray.reshape(p, 3, n).transpose(2, 0, 1)  # joint-major rows -> (N, P, 3)
    norm = np.linalg.norm(rays, axis=-1)
    visible = norm > 0
    if np.any(np.abs(norm[visible] - 1.0) > 1e-3):
        bad = float(norm[visible][np.argmax(np.abs(norm[visible] - 1.0))])
        raise ImportFormatError(
            f"{path}: field 'ray': expected unit rays or all-zero (missing), found norm {bad:.4g}"
        )
    try:
        px, R = rays_to_pixels(rays, visible, cam, K)
    except ValueError as exc:
        raise ImportFormatError(f"{path}: field 'ray': {exc}") from exc
    centres = C.T * scale
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = R[cam]
    T[:, :3, 3] = -np.einsum("nab,nb->na", R[cam], centres)
    stream = np.zeros(n, dtype=np.int32)
    for c in range(V):
        stream[cam == c] = np.arange(int(np.count_nonzero(cam == c)))
    log.info("%s: %d images, %d joints, %d cameras (units %s)", path, n, p, V, units)
    return ImportedCapture(
        source=str(path),
        skeleton=default_skeleton(p),
        cam_id=cam.astype(np.int32),
        stream_index=stream,
        K=K[cam],
        cam_from_world=T,
        keypoints_px=px,
        visible=visible,
        image_size=np.round(2.0 * K[:, :2, 2]).astype(np.int32),
        time_rank=np.arange(n, dtype=np.int64),
        points3d=X.reshape(p, 3, n).transpose(2, 0, 1) * scale,
    )
