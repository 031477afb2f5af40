"""Result views of a reconstructed recording: per-camera overlay videos, a 3-D animation, a timing plot.

:func:`render_result` reads a result written by ``gttnet reconstruct ... --out result.h5`` from a
recording, reloads the recording (its raw detections and calibration, lens distortion included) and
writes into ``out``:

* ``<camera>.mp4``: for each frame of that camera, the input 2-D keypoints (green circles, skeleton in
  grey) and the reconstruction projected back through the camera *with* its distortion (red crosses,
  skeleton in red), each joint labelled with its reprojection error in pixels, and the frame's mean
  error in the header;
* ``reprojection_error.csv``: mean and median error per camera and joint, pixels;
* ``skeleton_3d.mp4``: the 3-D skeleton in time order from an orbiting viewpoint (pyrender offscreen;
  skipped with a warning when no OpenGL backend is available);
* ``timing.png``: each camera's images on the result's time axis (clock times, or ranks when the
  result has no times), one row per camera.
"""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path

import cv2
import numpy as np

from gttdata.recording import Recording, RecordingSpec

__all__ = [
    "is_recording_result",
    "project_with_distortion",
    "render_capture_result",
    "render_result",
    "reprojection_errors",
]

log = logging.getLogger(__name__)

_GREEN, _RED, _GREY, _WHITE = (80, 200, 80), (60, 60, 230), (150, 150, 150), (235, 235, 235)


def project_with_distortion(points3d: np.ndarray, camera) -> np.ndarray:
    """World points to the camera's raw (distorted) pixels with OpenCV's ``projectPoints``.

    Args:
        points3d: World points, metres, shape ``(..., 3)``; NaN stays NaN.
        camera: A :class:`gttdata.cameras.Camera` (``K``, ``cam_from_world``, ``dist``).

    Returns:
        Pixels, shape ``(..., 2)``.
    """
    X = np.asarray(points3d, dtype=np.float64)
    flat = X.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    out = np.full((flat.shape[0], 2), np.nan)
    if ok.any():
        rvec, _ = cv2.Rodrigues(camera.R)
        px, _ = cv2.projectPoints(
            flat[ok].reshape(-1, 1, 3), rvec, camera.t, camera.K, np.asarray(camera.dist)
        )
        out[ok] = px.reshape(-1, 2)
    return out.reshape(X.shape[:-1] + (2,))


def _load(result: Path):
    import h5py

    with h5py.File(result, "r") as f:
        need = ("points3d", "cam_id", "frame")
        missing = [k for k in need if k not in f]
        if missing or not f.attrs.get("recording"):
            raise ValueError(
                f"{result}: field {missing[0] if missing else 'recording'!r} is missing; render needs a .h5 "
                "result of `gttnet reconstruct` run on a recording (--calibration/--keypoints or a project file)"
            )
        arrays = {k: f[k][()] for k in ("points3d", "cam_id", "frame", "time_s", "time_order") if k in f}
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    return arrays, attrs


def reprojection_errors(points3d: np.ndarray, cam_id: np.ndarray, frame: np.ndarray, rec: Recording):
    """Reprojection of every result row into its camera's raw detections.

    Args:
        points3d: Result joints, metres, shape ``(N, J, 3)``.
        cam_id: Camera index of each row, shape ``(N,)``.
        frame: Frame number of each row, shape ``(N,)``.
        rec: The recording (raw detections, calibration).

    Returns:
        ``(projected, detected, error)``: pixels ``(N, J, 2)``, pixels ``(N, J, 2)`` (NaN where not
        detected) and distances ``(N, J)`` in pixels (NaN where either is missing).
    """
    n, j = points3d.shape[:2]
    proj = np.full((n, j, 2), np.nan)
    det = np.full((n, j, 2), np.nan)
    for v, (kp, cam) in enumerate(zip(rec.keypoints, rec.rig.cameras, strict=True)):
        rows = np.flatnonzero(cam_id == v)
        if rows.size == 0:
            continue
        proj[rows] = project_with_distortion(points3d[rows], cam)
        pos = np.searchsorted(kp.frame, frame[rows])
        pos = np.minimum(pos, kp.n_frames - 1)
        hit = kp.frame[pos] == frame[rows]
        det[rows[hit]] = kp.xy[pos[hit]]
    err = np.linalg.norm(proj - det, axis=-1)
    return proj, det, err


def _draw_skeleton(img, px, bones, colour, thickness=1):
    for a, b in bones:
        if np.all(np.isfinite(px[[a, b]])):
            p, q = px[a].astype(int), px[b].astype(int)
            cv2.line(img, tuple(int(x) for x in p), tuple(int(x) for x in q), colour, thickness, cv2.LINE_AA)


def _window(pts: np.ndarray, size) -> tuple[np.ndarray, np.ndarray]:
    """Square window ``(lo, hi)`` in pixels around the subject (1st-99th percentile, 20 % margin)."""
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if pts.shape[0] < 2:
        return np.zeros(2), np.asarray(size, dtype=np.float64)
    lo, hi = np.percentile(pts, 1, axis=0), np.percentile(pts, 99, axis=0)
    centre, half = (lo + hi) / 2, 0.6 * float(np.max(hi - lo)) + 10.0
    return centre - half, centre + half


def _camera_video(path: Path, rows, proj, det, err, frames, name, size, bones, fps, width_px) -> Path:
    lo, hi = _window(np.concatenate([det[rows].reshape(-1, 2), proj[rows].reshape(-1, 2)]), size)
    scale = width_px / float(np.max(hi - lo))
    W = int(round(width_px)) // 2 * 2
    H = W + 32
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), float(fps), (W, H))
    if not writer.isOpened():
        raise OSError(f"{path}: OpenCV cannot write an mp4v video here")
    try:
        for n in rows:
            img = np.full((H, W, 3), 18, np.uint8)
            body = img[32:]
            d, q = (det[n] - lo) * scale, (proj[n] - lo) * scale
            _draw_skeleton(body, d, bones, _GREY)
            _draw_skeleton(body, q, bones, _RED)
            for jj in range(det.shape[1]):
                if np.all(np.isfinite(d[jj])):
                    cv2.circle(body, tuple(int(x) for x in d[jj]), 5, _GREEN, 1, cv2.LINE_AA)
                if np.all(np.isfinite(q[jj])):
                    c = tuple(int(x) for x in q[jj])
                    cv2.drawMarker(body, c, _RED, cv2.MARKER_CROSS, 8, 1, cv2.LINE_AA)
                    if np.isfinite(err[n, jj]):
                        cv2.putText(
                            body, f"{err[n, jj]:.1f}", (c[0] + 5, c[1] - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.33,
                            _WHITE, 1, cv2.LINE_AA,
                        )  # fmt: skip
            mean = np.nanmean(err[n]) if np.isfinite(err[n]).any() else np.nan
            label = f"{name}  frame {int(frames[n])}  mean reprojection error {mean:.2f} px"
            cv2.putText(img, label, (6, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.5, _WHITE, 1, cv2.LINE_AA)
            writer.write(img)
    finally:
        writer.release()
    return path


def _timing_plot(path: Path, cam_id, frame, time_s, names, timed: bool) -> Path:
    from gttdata.preview.plots import _figure, _save

    fig = _figure(7.0, 1.0 + 0.45 * len(names))
    ax = fig.add_subplot(1, 1, 1)
    for v in range(len(names)):
        sel = cam_id == v
        ax.scatter(time_s[sel], np.full(int(sel.sum()), v), s=6, marker="|")
    ax.set_yticks(range(len(names)), names)
    ax.set_xlabel("time (s)" if timed else "recovered rank (no clock)")
    ax.set_title("images per camera on the result's time axis")
    return _save(fig, path)


def _animation(
    path: Path, points, order, skeleton, fps: float, max_frames: int | None, progress: bool = False
) -> Path | None:
    """The 3-D skeleton in ``order``; every row, or every k-th row to stay within ``max_frames`` (said so)."""
    from tqdm import tqdm

    from gttdata.errors import PreviewDependencyError, RendererUnavailableError
    from gttdata.preview.render import orbit_camera, render_view

    step = 1 if not max_frames else max(1, int(np.ceil(len(order) / max_frames)))
    take = order[::step]
    if step > 1:
        log.warning(
            "%s: %d rows drawn as %d frames (every %d-th row, --max-frames %d): the animation plays %dx "
            "faster than the capture", path.name, len(order), len(take), step, max_frames, step,
        )  # fmt: skip
    size = (480, 480)
    try:
        K, T = orbit_camera(points[np.isfinite(points).all(-1)], image_size=size)
        first = render_view(points[take[0]], skeleton, K, T, size)
    except (PreviewDependencyError, RendererUnavailableError) as exc:
        log.warning("3-D animation skipped: %s", exc)
        return None
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), float(fps), (size[0], size[1]))
    try:
        bar = tqdm(take, desc=path.name, unit="frame", disable=not progress, leave=False)
        for k, n in enumerate(bar):
            rgb = first if k == 0 else render_view(points[n], skeleton, K, T, size)
            writer.write(np.ascontiguousarray(rgb[..., ::-1]))
    finally:
        writer.release()
    return path


def _error_table(path: Path, err: np.ndarray, cam_id: np.ndarray, names, joint_names) -> Path:
    """``reprojection_error.csv``: per camera and joint, the count, mean and median of ``err`` (N, J) pixels."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["camera", "joint", "n", "mean_px", "median_px"])
        for v, name in enumerate(names):
            e = err[cam_id == v]
            for jj, jn in enumerate(joint_names):
                col = e[:, jj][np.isfinite(e[:, jj])]
                mean, med = (f"{col.mean():.3f}", f"{np.median(col):.3f}") if col.size else ("", "")
                w.writerow([name, jn, col.size, mean, med])
    return path


def render_result(
    result: str | Path,
    out: str | Path,
    *,
    spec: RecordingSpec | None = None,
    video_fps: float | None = None,
    width_px: int = 640,
    animation: bool = True,
    max_3d_frames: int | None = None,
    progress: bool = False,
) -> dict[str, Path]:
    """Write the result views (see the module docstring) into ``out``.

    Args:
        result: ``.h5`` result of ``gttnet reconstruct`` on a recording.
        out: Output folder (created).
        spec: The recording (default: the one stored in the result).
        video_fps: Playback rate of the per-camera videos (default: the camera's rate, else 30).
        width_px: Width of the per-camera videos, pixels (each zooms onto the subject).
        animation: Also render the 3-D animation.
        max_3d_frames: At most this many frames in the 3-D animation (rows are subsampled, with a
            warning); None: every row.
        progress: Progress bars on stderr.

    Returns:
        The files written, by kind.
    """
    from gttnet.io.recording_input import spec_from_json

    result, out = Path(result), Path(out)
    arrays, attrs = _load(result)
    spec = spec or spec_from_json(attrs["recording"])
    rec = Recording.load(spec)
    names = json.loads(attrs.get("camera_names", "[]")) or list(rec.camera_names)
    if tuple(names) != rec.camera_names:
        raise ValueError(f"{result}: cameras {names} differ from the recording's {list(rec.camera_names)}")
    X, cam_id, frame = arrays["points3d"], arrays["cam_id"], arrays["frame"]
    proj, det, err = reprojection_errors(X, cam_id, frame, rec)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    bones = rec.skeleton.bones
    for v, cam in enumerate(rec.rig.cameras):
        rows = np.flatnonzero(cam_id == v)
        rows = rows[np.argsort(frame[rows], kind="stable")]
        fps = video_fps or (rec.fps[v] if np.isfinite(rec.fps[v]) else 30.0)
        written[cam.name] = _camera_video(
            out / f"{cam.name}.mp4",
            rows,
            proj,
            det,
            err,
            frame,
            cam.name,
            cam.image_size,
            bones,
            fps,
            width_px,
        )
    written["reprojection_error"] = _error_table(
        out / "reprojection_error.csv", err, cam_id, names, rec.skeleton.joint_names
    )
    time_s = arrays.get("time_s", np.full(X.shape[0], np.nan))
    timed = bool(np.isfinite(time_s).all())
    order = arrays.get("time_order", np.arange(X.shape[0]))
    if not timed:
        time_s = np.empty(X.shape[0])
        time_s[order] = np.arange(X.shape[0])
    written["timing"] = _timing_plot(out / "timing.png", cam_id, frame, time_s, names, timed)
    if animation:
        rate = float(np.nansum(rec.fps)) if np.isfinite(rec.fps).any() else 30.0
        anim = _animation(
            out / "skeleton_3d.mp4", X, order, rec.skeleton, min(rate, 30.0), max_3d_frames, progress
        )
        if anim is not None:
            written["skeleton_3d"] = anim
    finite = err[np.isfinite(err)]
    log.info("reprojection error: mean %.2f px, median %.2f px", finite.mean(), np.median(finite))
    return written


def is_recording_result(result: str | Path) -> bool:
    """Whether a ``gttnet reconstruct`` result was made from a recording (it stores the recording)."""
    import h5py

    try:
        with h5py.File(result, "r") as f:
            return bool(f.attrs.get("recording"))
    except OSError as exc:
        raise ValueError(f"{result}: expected a .h5 result of `gttnet reconstruct`, found {exc}") from exc


def render_capture_result(
    result: str | Path,
    out: str | Path,
    *,
    source: str | Path | None = None,
    sample: int = 0,
    units: str | None = None,
    fps: float = 30.0,
    animation: bool = True,
    max_3d_frames: int | None = None,
    progress: bool = False,
) -> dict[str, Path]:
    """Views of a result made from a capture file (GTT-Net JSON, DLOE ``.mat``, a shard), not a recording.

    Such a file holds viewing rays, not camera videos, so there are no overlay videos. Written into ``out``:
    ``reprojection_error.csv`` (each image's joints projected through its own camera pose, against the
    file's observations: mean and median pixels per camera and joint), ``skeleton_3d.mp4`` (every image in
    the result's recovered order) and ``timing.png`` (each camera's images on the recovered rank axis).

    Args:
        result: ``.h5`` result of ``gttnet reconstruct`` on a capture file.
        out: Output folder (created).
        source: The input file (default: the ``source`` the result records, relative to the working
            folder, else to the result's folder).
        sample: Sample index, for a shard or dataset source.
        units: Length unit of a source that records none (as given to ``reconstruct``).
        fps: Playback rate of the 3-D animation, frames per second.
        animation: Also render the 3-D animation.
        max_3d_frames: At most this many animation frames (rows subsampled, with a warning); None: all.
        progress: Progress bars on stderr.

    Returns:
        The files written, by kind.

    Raises:
        ValueError: The result or its source cannot be read, or they disagree (one line).
    """
    import h5py

    from gttnet.io import load_input

    result, out = Path(result), Path(out)
    with h5py.File(result, "r") as f:
        if "points3d" not in f or "image_index" not in f:
            raise ValueError(
                f"{result}: field 'points3d' or 'image_index' is missing; expected a reconstruct result"
            )
        X, index = f["points3d"][()], f["image_index"][()]
        rank = f["order"][()] if "order" in f else np.arange(X.shape[0])
        stored = f.attrs.get("source", "")
    stored = stored.decode() if isinstance(stored, bytes) else str(stored)
    src = Path(source) if source is not None else Path(stored)
    if source is None and not src.exists() and (result.parent / stored).exists():
        src = result.parent / stored
    if not str(src) or not src.exists():
        raise ValueError(f"{result}: its source {str(src)!r} was not found; pass the input file (--input)")
    loaded = load_input(src, sequencing="partial", sample=sample, units=units)
    obs = loaded.observations
    row_of = {int(k): i for i, k in enumerate(loaded.image_index)}
    if X.shape[1] != obs.keypoints_px.shape[1] or any(int(k) not in row_of for k in index):
        raise ValueError(
            f"{result}: its {X.shape[0]} images of {X.shape[1]} joints do not match {src} "
            f"({obs.keypoints_px.shape[0]} images of {obs.keypoints_px.shape[1]} joints)"
        )
    rows = np.array([row_of[int(k)] for k in index], dtype=np.int64)
    K, T = obs.K[rows], obs.cam_from_world[rows]
    cam = obs.cam_id[rows]
    Xc = np.einsum("nab,njb->nja", T[:, :3, :3], X) + T[:, None, :3, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        h = np.einsum("nab,njb->nja", K, Xc)
        proj = h[..., :2] / h[..., 2:3]
    det = np.where(obs.visible[rows][..., None], obs.keypoints_px[rows], np.nan)
    err = np.linalg.norm(proj - det, axis=-1)
    out.mkdir(parents=True, exist_ok=True)
    names = [f"cam_{v}" for v in range(int(cam.max()) + 1)]
    table = _error_table(out / "reprojection_error.csv", err, cam, names, obs.skeleton.joint_names)
    written: dict[str, Path] = {"reprojection_error": table}
    order = np.argsort(rank, kind="stable")
    written["timing"] = _timing_plot(
        out / "timing.png", cam, np.arange(len(cam)), rank.astype(float), names, False
    )
    if animation:
        anim = _animation(out / "skeleton_3d.mp4", X, order, obs.skeleton, fps, max_3d_frames, progress)
        if anim is not None:
            written["skeleton_3d"] = anim
    return written
