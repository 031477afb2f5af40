"""Simulate an unsynchronized multi-camera capture of a motion: timing, projection, noise, missing data."""

from __future__ import annotations

import logging
import string
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from gttdata.cameras import CameraRig
from gttdata.capture import realism
from gttdata.capture.noise import add_detection_noise
from gttdata.capture.occlusion import drop_images, drop_joints, visible_in_camera
from gttdata.capture.sample import CaptureSample, temporal_affinity
from gttdata.capture.timing import camera_offsets, min_cross_camera_gap, sample_timestamps
from gttdata.mocap.motion import Motion
from gttdata.skeleton import Skeleton

__all__ = ["CaptureParams", "merge_subjects", "project_images", "simulate_capture", "simulate_events"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CaptureParams:
    """Concrete capture parameters of one sample (the recipe's distributions, drawn).

    Args:
        fps_hz: Frame rate of each camera, Hz, length V.
        duration_s: Capture duration (of each event), seconds.
        stagger: Clock offset mode (see :data:`gttdata.capture.timing.STAGGER_MODES`).
        start_spread_s: Cameras started by hand before the capture: camera ``v`` started
            ``uniform(0, start_spread_s)`` seconds before its staggered offset, and its stream indices count
            its frames from that start (so two streams' indices differ by seconds' worth of frames).
        min_gap_s: Smallest time between any two images, seconds.
        jitter_s: Std of per-image timing jitter, seconds.
        drift_ppm: Clock rate error of each camera, ppm, length V.
        sigma_px: Std of the 2-D Gaussian noise, pixels.
        outlier_rate: Probability that an observed joint is an outlier.
        outlier_sigma_px: Std of an outlier's displacement, pixels.
        joint_drop_rate: Probability that a joint is dropped at random.
        image_drop_rate: Probability that a whole image is dropped.
        camera_motion: ``"fixed"`` or ``"ptz"`` (cameras pan and tilt after the subject; a pose per image).
        ptz_lag_s: Operator lag of a ``ptz`` camera, seconds.
        ptz_aim_deg: Std of a ``ptz`` camera's aiming error, degrees.
        ptz_subject_px: Zoom of a ``ptz`` camera (subject height, pixels; 0: fixed focal length).
        noise_corr_s: Correlation time of the detection noise along each camera's stream, seconds.
        swap_rate: Probability per image of a left/right swap of every mirrored joint pair.
        miss_run_frames: Mean length of the runs of missed joints, frames (<= 1: independent drops).
    """

    fps_hz: tuple[float, ...]
    duration_s: float
    stagger: str = "even"
    start_spread_s: float = 0.0
    min_gap_s: float = 1e-4
    jitter_s: float = 0.0
    drift_ppm: tuple[float, ...] = ()
    sigma_px: float = 0.0
    outlier_rate: float = 0.0
    outlier_sigma_px: float = 50.0
    joint_drop_rate: float = 0.0
    image_drop_rate: float = 0.0
    camera_motion: str = "fixed"
    ptz_lag_s: float = 0.3
    ptz_aim_deg: float = 1.0
    ptz_subject_px: float = 0.0
    noise_corr_s: float = 0.0
    swap_rate: float = 0.0
    miss_run_frames: float = 0.0

    def to_dict(self) -> dict:
        """JSON-serialisable form (lists for tuples); the realism fields only where they are switched on."""
        d = asdict(self)
        if self.camera_motion == "fixed":
            for k in ("camera_motion", "ptz_lag_s", "ptz_aim_deg", "ptz_subject_px"):
                d.pop(k)
        for k in ("noise_corr_s", "swap_rate", "miss_run_frames"):
            if d[k] == 0.0:
                d.pop(k)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def project_images(
    points3d: np.ndarray, K: np.ndarray, cam_from_world: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Project each image's joints with that image's camera.

    Args:
        points3d: Joints in world, metres, shape ``(N, J, 3)``.
        K: Intrinsics per image, pixels, shape ``(N, 3, 3)``.
        cam_from_world: World→camera transform per image, shape ``(N, 4, 4)``.

    Returns:
        ``(pixels, depth)``: shapes ``(N, J, 2)`` (NaN where depth <= 0) and ``(N, J)`` metres.
    """
    Xc = np.einsum("nab,njb->nja", cam_from_world[:, :3, :3], points3d) + cam_from_world[:, None, :3, 3]
    uvw = np.einsum("nab,njb->nja", K, Xc)
    depth = Xc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        px = uvw[..., :2] / uvw[..., 2:3]
    return np.where((depth > 0)[..., None], px, np.nan), depth


def merge_subjects(motions: Sequence[Motion], offsets_m: np.ndarray) -> Motion:
    """Several subjects as one motion whose skeleton stacks theirs (multi-subject captures).

    Subject ``s`` keeps its joints in order, named with the prefix ``"a_"``, ``"b_"``, ... and moved by
    ``offsets_m[s]``; joint ``s * J + j`` of the result is joint ``j`` of subject ``s``. The motions are
    resampled to the first one's rate and cut to the shortest.

    Args:
        motions: S motions sharing one skeleton (J joints).
        offsets_m: Translation of each subject in world, metres, shape ``(S, 3)``.

    Returns:
        A motion with ``S * J`` joints.
    """
    sk = motions[0].skeleton
    if any(m.skeleton.joint_names != sk.joint_names for m in motions):
        raise ValueError("merge_subjects: every motion must have the same skeleton joints")
    fps = motions[0].fps_hz
    ms = [m if m.fps_hz == fps else m.resample(fps) for m in motions]
    t = min(m.n_frames for m in ms)
    off = np.asarray(offsets_m, dtype=np.float64).reshape(len(ms), 1, 1, 3)
    pos = np.concatenate([m.positions[:t][None] for m in ms]) + off
    j = sk.n_joints
    merged = Skeleton(
        name=f"{sk.name}x{len(ms)}",
        joint_names=tuple(f"{string.ascii_lowercase[s]}_{n}" for s in range(len(ms)) for n in sk.joint_names),
        parents=tuple(p + s * j if p >= 0 else -1 for s in range(len(ms)) for p in sk.parents),
        mirror=tuple(q + s * j for s in range(len(ms)) for q in sk.mirror),
    )
    return Motion(
        positions=pos.transpose(1, 0, 2, 3).reshape(t, len(ms) * j, 3),
        fps_hz=fps,
        skeleton=merged,
        name="+".join(m.name for m in ms),
        provenance={"subjects": [m.name for m in ms], "n_subjects": len(ms)},
    )


def _timeline(params: CaptureParams, rng: np.random.Generator, n_cameras: int, total_s: float):
    fps = np.asarray(params.fps_hz, dtype=np.float64)
    if fps.shape != (n_cameras,):
        raise ValueError(f"params.fps_hz must have one rate per camera ({n_cameras}), got {fps.shape[0]}")
    drift = np.asarray(params.drift_ppm or (0.0,) * n_cameras, dtype=np.float64)
    offsets = camera_offsets(fps, stagger=params.stagger, rng=rng)
    if params.start_spread_s > 0:  # no draw otherwise: older recipes keep their random stream
        offsets = offsets - rng.uniform(0.0, params.start_spread_s, size=n_cameras)
    cam, t, frame = sample_timestamps(
        fps,
        total_s,
        offsets_s=offsets,
        rng=rng,
        jitter_s=params.jitter_s,
        drift_ppm=drift,
        min_gap_s=params.min_gap_s,
        frame_counter=params.start_spread_s > 0,
    )
    return cam, t, frame, offsets


def _stream_index(cam: np.ndarray) -> np.ndarray:
    si = np.zeros(cam.shape[0], dtype=np.int32)
    for v in np.unique(cam):
        idx = np.flatnonzero(cam == v)
        si[idx] = np.arange(idx.size)
    return si


def _event_affinity(
    t: np.ndarray, cam: np.ndarray, points: np.ndarray, event: np.ndarray, n_events: int
) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth temporal neighbours computed within each event, so two events are never linked."""
    nbr = np.full((t.shape[0], 2), -1, dtype=np.int32)
    w = np.zeros((t.shape[0], 2))
    for e in range(n_events):
        idx = np.flatnonzero(event == e)
        if idx.size:
            nb, ww = temporal_affinity(t[idx], cam[idx], points[idx])
            nbr[idx] = np.where(nb >= 0, idx[np.maximum(nb, 0)], -1)
            w[idx] = ww
    return nbr, w


def _simulate(
    segments: Sequence[tuple[Motion, float]],
    rig: CameraRig,
    params: CaptureParams,
    rng: np.random.Generator,
    *,
    name: str,
    motion_name: str,
) -> CaptureSample:
    """Core simulation; ``segments`` are ``(motion, start_s)``, each lasting ``params.duration_s``."""
    sk = segments[0][0].skeleton
    total = segments[-1][1] + params.duration_s
    cam, t, frame, offsets = _timeline(params, rng, len(rig), total)
    # Each image belongs to the event whose interval contains it; images in a gap are never taken.
    starts = np.array([s for _, s in segments])
    event = np.searchsorted(starts, t, side="right") - 1
    keep = (event >= 0) & (t < starts[np.maximum(event, 0)] + params.duration_s)
    cam, t, event, frame = cam[keep], t[keep], event[keep], frame[keep]
    if (
        params.start_spread_s <= 0
    ):  # streams numbered from their first image, as recipes before start_spread_s
        frame = _stream_index(cam)
    # A camera's video starts at its first kept frame's counter (0 unless it started before the capture).
    first = {int(v): int(frame[cam == v].min()) for v in np.unique(cam)}
    if params.image_drop_rate > 0:
        keep = drop_images(cam, rng, rate=params.image_drop_rate)
        cam, t, event, frame = cam[keep], t[keep], event[keep], frame[keep]
    n = t.shape[0]
    points = np.empty((n, sk.n_joints, 3))
    for e, (motion, start) in enumerate(segments):
        sel = event == e
        points[sel] = motion.sample_at(t[sel] - start)
    K = rig.K[cam]
    T = rig.cam_from_world[cam]
    if params.camera_motion == "ptz":
        T, K = realism.pan_tilt_zoom_poses(
            T,
            K,
            cam,
            t,
            points,
            rng,
            lag_s=params.ptz_lag_s,
            aim_deg=params.ptz_aim_deg,
            subject_px=params.ptz_subject_px,
        )
    size = np.array([c.image_size for c in rig.cameras], dtype=np.int32)
    gt_px, depth = project_images(points, K, T)
    lens = [list(c.dist) for c in rig.cameras]
    if np.any(np.asarray(lens, dtype=np.float64)):
        from gttdata.calibration import distort_points

        for v, c in enumerate(rig.cameras):  # images of a real lens: the pinhole points, distorted
            sel = cam == v
            gt_px[sel] = np.where((depth[sel] > 0)[..., None], distort_points(gt_px[sel], c), np.nan)
    noisy, outlier = add_detection_noise(
        gt_px,
        rng,
        sigma_px=params.sigma_px,
        outlier_rate=params.outlier_rate,
        outlier_sigma_px=params.outlier_sigma_px,
        correlate=(
            (lambda e: realism.correlate_along_streams(e, cam, t, corr_s=params.noise_corr_s))
            if params.noise_corr_s > 0
            else None
        ),
    )
    noisy, swapped = realism.swap_left_right(noisy, sk.mirror, rng, rate=params.swap_rate)
    if params.miss_run_frames > 1:
        kept = realism.missed_runs(
            cam, t, sk.n_joints, rng, rate=params.joint_drop_rate, mean_run=params.miss_run_frames
        )
    else:
        kept = drop_joints((n, sk.n_joints), rng, rate=params.joint_drop_rate)
    visible = visible_in_camera(gt_px, depth, size[cam]) & kept
    nbr, w = _event_affinity(t, cam, points, event, len(segments))
    meta = {
        "capture": params.to_dict(),
        "offsets_s": offsets.tolist(),
        "min_cross_camera_gap_s": min_cross_camera_gap(t, cam),
        "n_outliers": int((outlier & visible).sum()),
        "missing_rate": float(1.0 - visible.mean()) if visible.size else 0.0,
    }
    if params.swap_rate > 0:
        meta["n_swapped_images"] = int(swapped.sum())
    if params.image_drop_rate > 0:
        # What a camera's own timestamps reveal (frame k at k / fps on its clock): dropped frames as gaps,
        # where the stream index (the video's frame index) runs on without them.
        meta["frame_number"] = frame.astype(int).tolist()
    if len(segments) > 1:
        meta["event_id"] = event.astype(int).tolist()
        meta["event_start_s"] = starts.tolist()
    return CaptureSample(
        name=name,
        motion_name=motion_name,
        skeleton=sk,
        cam_id=cam.astype(np.int32),
        timestamp_s=t,
        stream_index=_stream_index(cam) + np.array([first[int(v)] for v in cam], dtype=np.int32),
        global_order=np.arange(n, dtype=np.int32),
        keypoints_px=np.where(visible[..., None], noisy, np.nan).astype(np.float32),
        visible=visible,
        keypoints_gt_px=gt_px.astype(np.float32),
        K=K,
        cam_from_world=T,
        image_size=size,
        points3d=points,
        affinity_nbr=nbr,
        affinity_w=w,
        meta=meta | ({"dist": lens} if np.any(np.asarray(lens, dtype=np.float64)) else {}),
    )


def simulate_capture(
    motion: Motion,
    rig: CameraRig,
    params: CaptureParams,
    rng: np.random.Generator,
    *,
    name: str,
    motion_name: str | None = None,
) -> CaptureSample:
    """Film ``motion`` with ``rig`` during ``[0, params.duration_s)`` of its timeline.

    Every image samples the motion at its own timestamp (linear interpolation), so cameras never share
    an instant. Joints behind the camera or outside the image, and randomly dropped ones, are missing.

    Args:
        motion: The subject (positions in world, metres); its time 0 is the capture's time 0.
        rig: V cameras.
        params: Concrete capture parameters (``len(params.fps_hz) == V``).
        rng: Random generator: the only source of randomness.
        name: Sample name.
        motion_name: Stored motion name (default ``motion.name``).

    Returns:
        The capture, images sorted by time; ``meta`` records every drawn parameter.
    """
    return _simulate([(motion, 0.0)], rig, params, rng, name=name, motion_name=motion_name or motion.name)


def simulate_events(
    motions: Sequence[Motion],
    rig: CameraRig,
    params: CaptureParams,
    rng: np.random.Generator,
    *,
    gaps_s: Sequence[float],
    name: str,
    motion_name: str | None = None,
) -> CaptureSample:
    """Film several temporally disjoint events: motion ``e`` plays during its own ``params.duration_s``.

    Events are separated by ``gaps_s`` during which no image is taken; ``meta["event_id"]`` (length N)
    labels each image with its event and the ground-truth affinity never links two events.

    Args:
        motions: One motion per event (same skeleton), each played from its time 0.
        rig: V cameras.
        params: Concrete capture parameters.
        rng: Random generator.
        gaps_s: Gap after each event but the last, seconds, length ``len(motions) - 1``.
        name: Sample name.
        motion_name: Stored motion name (default: the motion names joined by ``"|"``).
    """
    if len(gaps_s) != len(motions) - 1:
        raise ValueError(f"gaps_s must have {len(motions) - 1} entries, got {len(gaps_s)}")
    starts = np.concatenate([[0.0], np.cumsum(np.asarray(gaps_s, dtype=np.float64) + params.duration_s)])
    segments = list(zip(motions, starts.tolist(), strict=True))
    return _simulate(
        segments, rig, params, rng, name=name, motion_name=motion_name or "|".join(m.name for m in motions)
    )
