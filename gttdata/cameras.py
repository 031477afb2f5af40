"""Pinhole cameras and camera rigs: projection, viewing rays, and rig files.

Frame convention (used everywhere in gtt):
    * world: right-handed, z up, metres; the floor is z = 0.
    * camera: OpenCV, x right, y down, z forward (optical axis), metres.
    * ``cam_from_world`` is the 4x4 rigid transform taking world points into the camera frame,
      ``X_cam = R @ X_world + t`` with ``R = cam_from_world[:3, :3]``, ``t = cam_from_world[:3, 3]``.
      The camera centre in world is ``C = -R.T @ t``.
    * pixels: ``(u, v)`` with the origin at the top-left pixel's corner; ``[u, v, 1] ~ K @ X_cam``.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w

from gttdata.errors import RigError

__all__ = ["Camera", "CameraRig", "look_at", "ring_rig", "rotation_from_vector"]


def rotation_from_vector(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix of an axis-angle vector (Rodrigues' formula, as OpenCV's ``Rodrigues``), shape ``(3, 3)``.

    Args:
        rvec: Rotation axis times angle, radians, shape ``(3,)``; must be finite.

    Raises:
        ValueError: If ``rvec`` is not 3 finite numbers.

    Example:
        >>> rotation_from_vector(np.array([0.0, 0.0, np.pi / 2])).round(6).tolist()
        [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    r = np.asarray(rvec, dtype=np.float64).reshape(3)
    if not np.isfinite(r).all():
        raise ValueError(f"rotation vector must be finite, got {r.tolist()}")
    theta = float(np.linalg.norm(r))
    if theta < 1e-300:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    c, s = np.cos(theta), np.sin(theta)
    out: np.ndarray = c * np.eye(3) + (1.0 - c) * np.outer(k, k) + s * kx
    return out


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """``cam_from_world`` (4x4) of a camera at ``eye`` whose optical axis points at ``target``.

    Args:
        eye: Camera centre in world, metres, shape ``(3,)``.
        target: Point looked at in world, metres, shape ``(3,)``.
        up: World up direction, shape ``(3,)``; image ``-y`` points along it. Defaults to ``+z``.

    Example:
        >>> T = look_at(np.array([3.0, 0, 1]), np.zeros(3))
        >>> np.allclose(T[:3, :3] @ np.array([-3.0, 0, -1]) / np.sqrt(10), [0, 0, 1])
        True
    """
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - np.asarray(eye, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:  # looking straight along `up`: any horizontal x will do
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, y, z])
    T[:3, 3] = -T[:3, :3] @ np.asarray(eye, dtype=np.float64)
    return T


@dataclass(frozen=True)
class Camera:
    """A calibrated pinhole camera.

    Args:
        K: Intrinsics, pixels, shape ``(3, 3)``.
        cam_from_world: Rigid world→camera transform, shape ``(4, 4)`` (see module docstring).
        image_size: ``(width, height)`` in pixels.
        name: Camera name.
        dist: Distortion coefficients (OpenCV order k1, k2, p1, p2, k3). ``project`` is the pinhole
            projection and ignores them; the capture simulator distorts its images with them
            (:func:`gttdata.calibration.distort_points`) and readers of real recordings undo them
            (:func:`gttdata.calibration.undistort_points`).
    """

    K: np.ndarray
    cam_from_world: np.ndarray
    image_size: tuple[int, int] = (1000, 1000)
    name: str = "cam"
    dist: tuple[float, ...] = field(default=(0.0, 0.0, 0.0, 0.0, 0.0))

    def __post_init__(self) -> None:
        K = np.asarray(self.K, dtype=np.float64)
        T = np.asarray(self.cam_from_world, dtype=np.float64)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise RigError(f"camera {self.name!r}: K must be a finite (3, 3) matrix, got shape {K.shape}")
        if abs(np.linalg.det(K)) < 1e-12 or K[2, 2] == 0:
            raise RigError(f"camera {self.name!r}: K must be non-singular, got det {np.linalg.det(K):.3g}")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise RigError(f"camera {self.name!r}: cam_from_world must be finite (4, 4), got {T.shape}")
        R = T[:3, :3]
        err = np.abs(R @ R.T - np.eye(3)).max()
        if err > 1e-6 or np.linalg.det(R) < 0:
            raise RigError(
                f"camera {self.name!r}: rotation must be orthonormal with det +1, got |RR^T - I| = {err:.3g}, "
                f"det = {np.linalg.det(R):.3g}"
            )
        if not np.allclose(T[3], [0, 0, 0, 1]):
            raise RigError(f"camera {self.name!r}: cam_from_world last row must be [0, 0, 0, 1], got {T[3]}")
        w, h = (int(v) for v in self.image_size)
        if w <= 0 or h <= 0:
            raise RigError(f"camera {self.name!r}: image_size must be positive (width, height), got {(w, h)}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "cam_from_world", T)
        object.__setattr__(self, "image_size", (w, h))
        object.__setattr__(self, "dist", tuple(float(d) for d in self.dist))

    @property
    def R(self) -> np.ndarray:
        """World→camera rotation, shape ``(3, 3)``."""
        return self.cam_from_world[:3, :3]

    @property
    def t(self) -> np.ndarray:
        """World→camera translation in metres, shape ``(3,)``."""
        return self.cam_from_world[:3, 3]

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world, metres, shape ``(3,)``."""
        return -self.R.T @ self.t

    @property
    def world_from_cam(self) -> np.ndarray:
        """Camera→world transform, shape ``(4, 4)``."""
        return np.linalg.inv(self.cam_from_world)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points to pixels.

        Args:
            points: World points in metres, shape ``(..., 3)``.

        Returns:
            ``(pixels, depth)``: pixels of shape ``(..., 2)`` and depth along the optical axis in metres,
            shape ``(...)``. Points behind the camera (depth <= 0) still get a (meaningless) pixel.

        Example:
            >>> cam = Camera(np.diag([1000.0, 1000, 1]), np.eye(4))
            >>> px, d = cam.project(np.array([0.1, 0.2, 2.0]))
            >>> px.tolist(), float(d)
            ([50.0, 100.0], 2.0)
        """
        X = np.asarray(points, dtype=np.float64)
        Xc = X @ self.R.T + self.t
        depth = Xc[..., 2]
        uvw = Xc @ self.K.T
        with np.errstate(divide="ignore", invalid="ignore"):
            px = uvw[..., :2] / uvw[..., 2:3]
        return px, depth

    def pixel_rays(self, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Viewing rays through pixels.

        Args:
            pixels: Pixel coordinates, shape ``(..., 2)``.

        Returns:
            ``(origins, directions)`` in world, each shape ``(..., 3)``; directions are unit vectors
            pointing in front of the camera, ``r = R^T K^-1 [u, v, 1]^T / norm``.
        """
        px = np.asarray(pixels, dtype=np.float64)
        h = np.concatenate([px, np.ones(px.shape[:-1] + (1,))], axis=-1)
        d = h @ np.linalg.inv(self.K).T @ self.R
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return np.broadcast_to(self.center, d.shape).copy(), d

    def in_image(self, pixels: np.ndarray) -> np.ndarray:
        """Whether pixels lie inside the image, shape ``(...)`` bool."""
        w, h = self.image_size
        return (pixels[..., 0] >= 0) & (pixels[..., 0] < w) & (pixels[..., 1] >= 0) & (pixels[..., 1] < h)


@dataclass(frozen=True)
class CameraRig:
    """A set of V cameras.

    Args:
        cameras: The cameras, length V.
    """

    cameras: tuple[Camera, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "cameras", tuple(self.cameras))
        if not self.cameras:
            raise RigError("rig must have at least one camera, got 0")

    def __len__(self) -> int:
        return len(self.cameras)

    def __getitem__(self, i: int) -> Camera:
        return self.cameras[i]

    @property
    def K(self) -> np.ndarray:
        """Intrinsics of every camera, shape ``(V, 3, 3)``."""
        return np.stack([c.K for c in self.cameras])

    @property
    def cam_from_world(self) -> np.ndarray:
        """Extrinsics of every camera, shape ``(V, 4, 4)``."""
        return np.stack([c.cam_from_world for c in self.cameras])

    def to_dict(self) -> dict:
        """Rig in the aniposelib / Pose2Sim calibration layout (one table per camera)."""
        out = {}
        for i, c in enumerate(self.cameras):
            import cv2  # imported on use: 0.05-0.1 s of start-up

            rvec, _ = cv2.Rodrigues(c.R)
            out[f"cam_{i}"] = {
                "name": c.name,
                "size": [int(c.image_size[0]), int(c.image_size[1])],
                "matrix": c.K.tolist(),
                "distortions": list(c.dist),
                "rotation": rvec.ravel().tolist(),
                "translation": c.t.tolist(),
                "fisheye": False,
            }
        out["metadata"] = {"adjusted": False, "error": 0.0, "units": "m", "frame": "cam_from_world"}
        return out

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "<dict>") -> CameraRig:
        """Parse the aniposelib / Pose2Sim layout; raises RigError naming the table and field."""
        cams = []
        for key, tab in d.items():
            if key == "metadata":
                continue
            if not isinstance(tab, dict):
                raise RigError(f"{source}: [{key}] must be a table, found {type(tab).__name__}")
            for f in ("size", "matrix", "rotation", "translation"):
                if f not in tab:
                    raise RigError(f"{source}: [{key}] field {f!r} is missing")
            try:
                R = rotation_from_vector(np.asarray(tab["rotation"], dtype=np.float64).reshape(3))
                T = np.eye(4)
                T[:3, :3] = R
                T[:3, 3] = np.asarray(tab["translation"], dtype=np.float64).reshape(3)
                dist = tuple(float(v) for v in np.asarray(tab.get("distortions", [0.0] * 5)).ravel())
                size = tuple(int(round(float(v))) for v in tab["size"])
                K = np.asarray(tab["matrix"], dtype=np.float64)
            except (ValueError, TypeError, OverflowError) as exc:
                raise RigError(f"{source}: [{key}] has a malformed field: {exc}") from exc
            if len(size) != 2:
                raise RigError(f"{source}: [{key}] field 'size' must be [width, height], found {tab['size']}")
            try:
                cams.append(
                    Camera(K=K, cam_from_world=T, image_size=size, name=str(tab.get("name", key)), dist=dist)
                )
            except RigError as exc:
                raise RigError(f"{source}: [{key}] {exc}") from exc
        if not cams:
            raise RigError(f"{source}: no camera tables found")
        return cls(tuple(cams))

    def save(self, path: str | Path) -> None:
        """Write as ``.toml`` (aniposelib / Pose2Sim) or ``.json`` by suffix."""
        path = Path(path)
        d = self.to_dict()
        text = json.dumps(d, indent=2) if path.suffix == ".json" else tomli_w.dumps(d)
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(text)
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path) -> CameraRig:
        """Read a ``.toml`` or ``.json`` rig file."""
        path = Path(path)
        try:
            raw = path.read_bytes()
        except FileNotFoundError as exc:
            raise RigError(f"{path}: rig file not found") from exc
        try:
            d = json.loads(raw) if path.suffix == ".json" else tomllib.loads(raw.decode())
        except (json.JSONDecodeError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise RigError(f"{path}: cannot parse rig file: {exc}") from exc
        return cls.from_dict(d, source=str(path))


def ring_rig(
    n_cameras: int = 4,
    *,
    radius_m: float = 3.0,
    height_m: float = 1.0,
    target: tuple[float, float, float] = (0.0, 0.0, 0.9),
    f_px: float = 1000.0,
    image_size: tuple[int, int] = (1000, 1000),
    start_angle_deg: float = 0.0,
    jitter_m: float = 0.0,
    jitter_deg: float = 0.0,
    rng: np.random.Generator | None = None,
) -> CameraRig:
    """A ring of cameras around ``target``, evenly spread in azimuth, all aimed at the target.

    The paper's default is 4 cameras, 1000x1000 px, f = 1000 px, about 3 m from the subject.

    Args:
        n_cameras: Number of cameras V.
        radius_m: Horizontal distance of each camera from the target, metres.
        height_m: Camera height above the floor, metres.
        target: Aim point in world, metres.
        f_px: Focal length in pixels; the principal point is the image centre.
        image_size: ``(width, height)`` in pixels.
        start_angle_deg: Azimuth of the first camera.
        jitter_m: Std of a Gaussian perturbation of each centre, metres.
        jitter_deg: Std of a Gaussian perturbation of each azimuth, degrees.
        rng: Random generator for the jitter (required when a jitter is non-zero).
    """
    if n_cameras < 1:
        raise RigError(f"n_cameras must be >= 1, got {n_cameras}")
    if (jitter_m or jitter_deg) and rng is None:
        raise ValueError("ring_rig: rng is required when jitter_m or jitter_deg is non-zero")
    w, h = image_size
    K = np.array([[f_px, 0.0, w / 2.0], [0.0, f_px, h / 2.0], [0.0, 0.0, 1.0]])
    tgt = np.asarray(target, dtype=np.float64)
    cams = []
    for i in range(n_cameras):
        az = np.deg2rad(start_angle_deg + 360.0 * i / n_cameras)
        if jitter_deg:
            assert rng is not None  # checked above
            az += np.deg2rad(rng.normal(0.0, jitter_deg))
        eye = np.array([tgt[0] + radius_m * np.cos(az), tgt[1] + radius_m * np.sin(az), height_m])
        if jitter_m:
            assert rng is not None  # checked above
            eye = eye + rng.normal(0.0, jitter_m, size=3)
        cams.append(Camera(K=K.copy(), cam_from_world=look_at(eye, tgt), image_size=(w, h), name=f"cam_{i}"))
    return CameraRig(tuple(cams))
