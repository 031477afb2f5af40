"""3-D skeleton rendering with pyrender from rig and orbit cameras, and the per-sample preview writer."""

from __future__ import annotations

import logging
import sys
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from gttdata.cameras import look_at
from gttdata.capture.sample import CaptureSample
from gttdata.preview._gl import (
    PreviewDependencyError,
    RendererUnavailableError,
    offscreen_renderer,
    require,
)
from gttdata.preview._style import LEFT, RIGHT, bone_rgb, joint_rgb, joint_sides
from gttdata.skeleton import Skeleton

__all__ = [
    "opengl_camera_pose",
    "front_azimuth_deg",
    "orbit_camera",
    "render_joint_labels",
    "render_sample_3d",
    "render_samples",
    "render_view",
    "sample_stem",
]

_log = logging.getLogger(__name__)

_BACKGROUND = (0.12, 0.12, 0.14, 1.0)
_FLOOR_RGB = (0.22, 0.22, 0.24)
_GRID_RGB = (0.45, 0.45, 0.48)
_ZNEAR_M, _ZFAR_M = 0.05, 200.0
# OpenCV camera axes (x right, y down, z forward) -> OpenGL camera axes (x right, y up, z backward).
_CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def opengl_camera_pose(cam_from_world: np.ndarray) -> np.ndarray:
    """Camera node pose for pyrender for an OpenCV extrinsic: ``world_from_cam @ diag(1, -1, -1, 1)``.

    Args:
        cam_from_world: World→camera (OpenCV axes) transform, shape ``(4, 4)``.

    Returns:
        World pose of the OpenGL camera (looking along its ``-z``), shape ``(4, 4)``.

    Example:
        >>> pose = opengl_camera_pose(look_at(np.array([3.0, 0, 1]), np.array([0.0, 0, 1])))
        >>> np.allclose(pose[:3, 2], [1, 0, 0]), np.allclose(pose[:3, 1], [0, 0, 1])
        (True, True)
    """
    return np.linalg.inv(np.asarray(cam_from_world, dtype=np.float64)) @ _CV_TO_GL


def orbit_camera(
    points3d: np.ndarray,
    *,
    azimuth_deg: float = 30.0,
    elevation_deg: float = 20.0,
    image_size: tuple[int, int] = (480, 480),
    fov_deg: float = 40.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A camera on a sphere around the skeleton, framing all of it.

    Args:
        points3d: World joints, metres, shape ``(J, 3)``.
        azimuth_deg: Angle around world ``+z`` from ``+x``.
        elevation_deg: Angle above the horizontal plane through the skeleton's centre.
        image_size: ``(width, height)`` in pixels.
        fov_deg: Vertical field of view.

    Returns:
        ``(K, cam_from_world)``: intrinsics ``(3, 3)`` and OpenCV extrinsic ``(4, 4)``.
    """
    p = np.asarray(points3d, dtype=np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    lo, hi = (p.min(axis=0), p.max(axis=0)) if len(p) else (np.zeros(3), np.ones(3))
    centre = (lo + hi) / 2
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.3)
    w, h = image_size
    f = 0.5 * h / np.tan(np.deg2rad(fov_deg) / 2)
    dist = 1.15 * radius / np.sin(np.deg2rad(fov_deg) / 2 * min(1.0, w / h))
    az, el = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    eye = centre + dist * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    K = np.array([[f, 0.0, w / 2], [0.0, f, h / 2], [0.0, 0.0, 1.0]])
    return K, look_at(eye, centre)


def front_azimuth_deg(points3d: np.ndarray, skeleton: Skeleton) -> float | None:
    """Azimuth (degrees around world ``+z`` from ``+x``) of the direction the skeleton faces.

    The facing direction is ``left x z`` for ``left`` the mean left joint minus the mean right joint
    (``_style.joint_sides``), projected on the floor; None when the skeleton has no finite left/right pair.

    Args:
        points3d: World joints, metres, shape ``(J, 3)``.
        skeleton: Topology of the J joints.
    """
    p = np.asarray(points3d, dtype=np.float64)
    sides = joint_sides(skeleton)
    ok = np.isfinite(p).all(axis=1)
    lm, rm = ok & (sides == LEFT), ok & (sides == RIGHT)
    if not lm.any() or not rm.any():
        return None
    left = p[lm].mean(axis=0) - p[rm].mean(axis=0)
    fwd = np.cross(left * (1.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    if np.linalg.norm(fwd[:2]) < 1e-9:
        return None
    return float(np.rad2deg(np.arctan2(fwd[1], fwd[0])))


def _material(pyrender, rgb: tuple[float, float, float]):
    return pyrender.MetallicRoughnessMaterial(
        baseColorFactor=(float(rgb[0]), float(rgb[1]), float(rgb[2]), 1.0),
        metallicFactor=0.0,
        roughnessFactor=0.7,
    )


def _floor_nodes(pyrender, trimesh, centre_xy: np.ndarray, half_m: float, step_m: float) -> list:
    """A dark floor plane at z = 0 with a grid of thin light lines every ``step_m``."""
    c = np.round(np.asarray(centre_xy) / step_m) * step_m
    n = int(np.ceil(half_m / step_m))
    size = 2 * n * step_m
    plane = trimesh.creation.box(extents=(size, size, 0.002))
    plane.apply_translation((c[0], c[1], -0.002))
    lines = []
    for k in range(-n, n + 1):
        for along_x in (True, False):
            box = trimesh.creation.box(extents=(size, 0.012, 0.001) if along_x else (0.012, size, 0.001))
            off = (0.0, k * step_m) if along_x else (k * step_m, 0.0)
            box.apply_translation((c[0] + off[0], c[1] + off[1], 0.0))
            lines.append(box)
    grid = trimesh.util.concatenate(lines)
    return [
        pyrender.Mesh.from_trimesh(plane, material=_material(pyrender, _FLOOR_RGB), smooth=False),
        pyrender.Mesh.from_trimesh(grid, material=_material(pyrender, _GRID_RGB), smooth=False),
    ]


def _skeleton_meshes(
    pyrender,
    trimesh,
    points3d: np.ndarray,
    skeleton: Skeleton,
    *,
    joint_radius_m: float,
    bone_radius_m: float,
) -> list:
    """Joint spheres (instanced) and bone cylinders, one mesh per colour (``_style.joint_rgb``)."""
    p = np.asarray(points3d, dtype=np.float64)
    ok = np.asarray(np.isfinite(p).all(axis=1))
    jrgb, brgb = joint_rgb(skeleton), bone_rgb(skeleton)
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=joint_radius_m)
    meshes = []
    for rgb in np.unique(np.concatenate([jrgb, brgb]), axis=0):
        idx = np.flatnonzero((jrgb == rgb).all(axis=1) & ok)
        if len(idx):
            poses = np.tile(np.eye(4), (len(idx), 1, 1))
            poses[:, :3, 3] = p[idx]
            meshes.append(pyrender.Mesh.from_trimesh(sphere, material=_material(pyrender, rgb), poses=poses))
        cyl = []
        for (a, b), c in zip(skeleton.limbs, brgb, strict=True):
            same = bool((c == rgb).all())
            if same and ok[a] and ok[b] and np.linalg.norm(p[a] - p[b]) > 1e-6 and bone_radius_m > 0:
                cyl.append(trimesh.creation.cylinder(radius=bone_radius_m, segment=(p[a], p[b]), sections=10))
        if cyl:
            meshes.append(
                pyrender.Mesh.from_trimesh(trimesh.util.concatenate(cyl), material=_material(pyrender, rgb))
            )
    return meshes


def _joint_radius(points3d: np.ndarray, skeleton: Skeleton) -> float:
    """A sphere radius that suits the skeleton's size: a fifth of the median limb length, 4-35 mm."""
    limbs = skeleton.limbs
    if not len(limbs):
        return 0.035
    length = np.linalg.norm(points3d[limbs[:, 0]] - points3d[limbs[:, 1]], axis=-1)
    length = length[np.isfinite(length) & (length > 1e-6)]
    return float(np.clip(0.2 * np.median(length), 0.004, 0.035)) if len(length) else 0.035


def _scaled(K: np.ndarray, image_size, scale: float) -> tuple[np.ndarray, int, int]:
    """Intrinsics and size for an image resampled by ``scale`` (pixel-corner origin, so ``K' = S K``)."""
    Ks = np.diag([scale, scale, 1.0]) @ np.asarray(K, dtype=np.float64)
    w, h = (max(1, int(round(v * scale))) for v in image_size)
    return Ks, w, h


def render_view(
    points3d: np.ndarray,
    skeleton: Skeleton,
    K: np.ndarray,
    cam_from_world: np.ndarray,
    image_size: tuple[int, int],
    *,
    scale: float = 1.0,
    floor: bool = True,
    flat: bool = False,
    joint_radius_m: float | None = None,
    bone_radius_m: float | None = None,
) -> np.ndarray:
    """Render the skeleton (bones as cylinders, joints as spheres) on a floor grid from a pinhole camera.

    Left joints/bones are blue, right ones orange-red, midline grey; several stacked subjects get one hue
    each (see ``_style.joint_rgb``).

    Args:
        points3d: World joints, metres, shape ``(J, 3)``; non-finite joints are left out.
        skeleton: Topology of the J joints.
        K: Intrinsics of the camera, pixels, shape ``(3, 3)``.
        cam_from_world: OpenCV world→camera transform, shape ``(4, 4)``.
        image_size: ``(width, height)`` of the camera in pixels.
        scale: Output resolution relative to ``image_size`` (the intrinsics are scaled to match).
        floor: Draw the z = 0 floor grid.
        flat: Unlit base colours (``RenderFlags.FLAT``) instead of a camera headlight.
        joint_radius_m: Sphere radius, metres; None: scaled to the skeleton (a fifth of its median limb
            length, between 4 mm and 35 mm), so that a hand and a person both read well.
        bone_radius_m: Cylinder radius, metres (0: no bones); None: half the joint radius.

    Returns:
        RGB image, shape ``(round(h * scale), round(w * scale), 3)`` uint8.

    Raises:
        PreviewDependencyError, RendererUnavailableError: No trimesh/pyrender or no GL backend.
    """
    Ks, w, h = _scaled(K, image_size, scale)
    pyrender, renderer = offscreen_renderer(w, h)
    trimesh = require("trimesh")
    scene = pyrender.Scene(bg_color=_BACKGROUND, ambient_light=(0.35, 0.35, 0.35))
    p = np.asarray(points3d, dtype=np.float64)
    if joint_radius_m is None:
        joint_radius_m = _joint_radius(p, skeleton)
    if bone_radius_m is None:
        bone_radius_m = 0.5 * joint_radius_m
    for mesh in _skeleton_meshes(
        pyrender, trimesh, p, skeleton, joint_radius_m=joint_radius_m, bone_radius_m=bone_radius_m
    ):
        scene.add(mesh)
    if floor:
        finite = p[np.isfinite(p).all(axis=1)]
        centre = finite[:, :2].mean(axis=0) if len(finite) else np.zeros(2)
        for mesh in _floor_nodes(pyrender, trimesh, centre, half_m=3.0, step_m=0.5):
            scene.add(mesh)
    pose = opengl_camera_pose(cam_from_world)
    cam = pyrender.IntrinsicsCamera(Ks[0, 0], Ks[1, 1], Ks[0, 2], Ks[1, 2], znear=_ZNEAR_M, zfar=_ZFAR_M)
    scene.add(cam, pose=pose)
    scene.add(pyrender.DirectionalLight(color=(1.0, 1.0, 1.0), intensity=3.0), pose=pose)
    flags = pyrender.RenderFlags.FLAT if flat else pyrender.RenderFlags.NONE
    color, _ = renderer.render(scene, flags=flags)
    return np.ascontiguousarray(color[..., :3])


def render_joint_labels(
    points3d: np.ndarray,
    K: np.ndarray,
    cam_from_world: np.ndarray,
    image_size: tuple[int, int],
    *,
    joint_radius_m: float = 0.01,
) -> np.ndarray:
    """Segmentation render of the joint spheres alone: which joint each pixel sees (no lighting, no blending).

    Ties the renderer's camera model to :meth:`gttdata.cameras.Camera.project`: the centroid of label j
    lies at joint j's projection.

    Args:
        points3d: World joints, metres, shape ``(J, 3)``; J < 65535.
        K: Intrinsics, pixels, shape ``(3, 3)``.
        cam_from_world: OpenCV world→camera transform, shape ``(4, 4)``.
        image_size: ``(width, height)`` in pixels.
        joint_radius_m: Sphere radius, metres.

    Returns:
        Joint index per pixel, ``-1`` for background, shape ``(height, width)`` int32.
    """
    w, h = (int(v) for v in image_size)
    pyrender, renderer = offscreen_renderer(w, h)
    trimesh = require("trimesh")
    p = np.asarray(points3d, dtype=np.float64)
    if len(p) >= 65535:
        raise ValueError(f"render_joint_labels: at most 65534 joints, got {len(p)}")
    scene = pyrender.Scene(bg_color=(0.0, 0.0, 0.0, 1.0))
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=joint_radius_m)
    seg = {}
    for j in np.flatnonzero(np.isfinite(p).all(axis=1)):
        pose = np.eye(4)
        pose[:3, 3] = p[j]
        node = scene.add(pyrender.Mesh.from_trimesh(sphere), pose=pose)
        seg[node] = ((j + 1) % 256, (j + 1) // 256, 0)  # label j + 1 in two channels; 0 = background
    cam = pyrender.IntrinsicsCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], znear=_ZNEAR_M, zfar=_ZFAR_M)
    scene.add(cam, pose=opengl_camera_pose(cam_from_world))
    color, _ = renderer.render(scene, flags=pyrender.RenderFlags.SEG, seg_node_map=seg)
    return color[..., 0].astype(np.int32) + 256 * color[..., 1].astype(np.int32) - 1


def _label(img: np.ndarray, text: str) -> None:
    cv2.putText(img, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)


#: The orbit view looks at the skeleton from this far off its front (degrees) and this far above the
#: horizontal: a near-front view, in which left and right limbs stay apart (a side view crosses the legs).
ORBIT_FROM_FRONT_DEG = 20.0
ORBIT_ELEVATION_DEG = 15.0


def render_sample_3d(sample: CaptureSample, *, tile_px: int = 320, time_s: float | None = None) -> np.ndarray:
    """One row of 3-D renders: from each rig camera's exact intrinsics and pose, then from an orbit camera.

    The orbit camera takes a near-front view of the skeleton at that instant
    (:func:`front_azimuth_deg` plus :data:`ORBIT_FROM_FRONT_DEG`, elevation :data:`ORBIT_ELEVATION_DEG`).

    For each camera the image closest to ``time_s`` is used (its own K, pose and ground-truth joints);
    the ground-truth 2-D projections are marked with small white rings, which sit on the rendered
    joints when the renderer and :meth:`Camera.project` agree.

    Args:
        sample: The capture.
        tile_px: Longest side of each tile, pixels.
        time_s: Instant to show, seconds (default: the median timestamp).

    Returns:
        RGB image, shape ``(tile_px, W, 3)`` uint8 (tiles keep each camera's aspect ratio).
    """
    t = float(np.median(sample.timestamp_s)) if time_s is None else float(time_s)
    tiles = []
    for v in range(sample.n_cameras):
        idx = np.flatnonzero(sample.cam_id == v)
        if not len(idx):
            continue
        n = int(idx[np.argmin(np.abs(sample.timestamp_s[idx] - t))])
        w, h = (int(x) for x in sample.image_size[v])
        size = (w, h)
        s = tile_px / max(size)
        img = render_view(
            sample.points3d[n], sample.skeleton, sample.K[n], sample.cam_from_world[n], size, scale=s
        )
        img = np.ascontiguousarray(img)
        for u, vv in sample.keypoints_gt_px[n] * s:
            if np.isfinite(u) and np.isfinite(vv):
                cv2.circle(
                    img, (int(round(u * 16)), int(round(vv * 16))), 3 * 16, (255, 255, 255), 1, cv2.LINE_AA, 4
                )
        _label(img, f"cam {v}  t={sample.timestamp_s[n]:.3f}s")
        tiles.append(np.pad(img, ((0, tile_px - img.shape[0]), (0, 2), (0, 0))))
    n = int(np.argmin(np.abs(sample.timestamp_s - t)))
    front = front_azimuth_deg(sample.points3d[n], sample.skeleton)
    K, T = orbit_camera(
        sample.points3d[n],
        azimuth_deg=30.0 if front is None else front + ORBIT_FROM_FRONT_DEG,
        elevation_deg=ORBIT_ELEVATION_DEG,
        image_size=(tile_px, tile_px),
    )
    orbit = render_view(sample.points3d[n], sample.skeleton, K, T, (tile_px, tile_px))
    orbit = np.ascontiguousarray(orbit)
    _label(orbit, f"orbit  t={sample.timestamp_s[n]:.3f}s")
    tiles.append(orbit)
    return np.concatenate(tiles, axis=1)


def sample_stem(sample: CaptureSample) -> str:
    """File-name stem of a sample's previews, e.g. ``train-000017`` or ``train-000017-global_rotation``."""
    stem = sample.name.replace("/", "-").replace("\\", "-")
    return stem if sample.variant == "orig" else f"{stem}-{sample.variant}"


def _write_png(path: Path, rgb: np.ndarray) -> Path:
    if not cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise OSError(f"{path}: cannot write PNG")
    return path


def render_samples(
    samples: Iterable[CaptureSample],
    out_dir: Path,
    *,
    video: bool = False,
    progress: bool = True,
    render_3d: bool | None = None,
    plots: bool = True,
    sheet_images: int | None = 48,
) -> list[Path]:
    """Write the previews of each sample into ``out_dir``; returns the written paths.

    Per sample (stem from :func:`sample_stem`): ``<stem>_contact.png`` (2-D overlays, cameras x time;
    further pages of at most 16 columns as ``<stem>_contact_p2.png``, ...),
    ``<stem>_3d.png`` (:func:`render_sample_3d`), ``<stem>_timestamps.png`` (raster, needs matplotlib)
    and, with ``video``, ``<stem>.mp4``.

    Args:
        samples: Captures to preview.
        out_dir: Output directory (created).
        video: Also write an MP4 of each sample in global time order.
        progress: tqdm progress bar on stderr.
        render_3d: True: 3-D views, failing without GL; False: none; None: when a GL backend works
            (otherwise one warning is logged).
        plots: Timestamp raster per sample when matplotlib is installed.
        sheet_images: Images (columns) per contact sheet, the first in time (None: all).

    Raises:
        RendererUnavailableError, PreviewDependencyError: Only with ``render_3d=True``.
    """
    from tqdm import tqdm

    from gttdata.preview.overlay import contact_sheets, write_video

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    samples = list(samples)
    for sample in tqdm(samples, desc="preview", unit="sample", disable=not progress, file=sys.stderr):
        stem = sample_stem(sample)
        for page, sheet in enumerate(contact_sheets(sample, max_images=sheet_images)):
            name = f"{stem}_contact.png" if page == 0 else f"{stem}_contact_p{page + 1}.png"
            written.append(_write_png(out_dir / name, cv2.cvtColor(sheet, cv2.COLOR_BGR2RGB)))
        if render_3d is not False:
            try:
                written.append(_write_png(out_dir / f"{stem}_3d.png", render_sample_3d(sample)))
            except (RendererUnavailableError, PreviewDependencyError) as exc:
                if render_3d:
                    raise
                _log.warning("3-D previews skipped: %s", exc)
                render_3d = False
        if plots:
            try:
                from gttdata.preview.plots import plot_timestamp_raster

                written.append(plot_timestamp_raster(sample, out_dir / f"{stem}_timestamps.png"))
            except PreviewDependencyError as exc:
                _log.warning("plots skipped: %s", exc)
                plots = False
        if video:
            written.append(write_video(sample, out_dir / f"{stem}.mp4"))
    return written
