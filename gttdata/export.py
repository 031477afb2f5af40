"""Export a simulated capture as a real recording: detector files, a calibration, timestamps, a project file.

``export_capture(sample, out)`` writes, for camera ``v`` named ``cam_<v>``:

* its 2-D detections (``cam_<v>/`` OpenPose JSON files, or ``cam_<v>.csv``/``.h5`` DeepLabCut
  predictions), one row per image in stream order with the frame number = the stream index;
* ``cam_<v>_timestamps.csv``: each frame's time as ``ffprobe`` writes it (``frame,<seconds>``) on
  the camera's own clock (its first frame at 0), or on the capture's clock with ``shared_clock``;

plus ``calibration.toml`` (aniposelib / Pose2Sim layout, translations in ``units``, with the lens
distortion the capture was simulated with), ``project.toml`` (every path above) and
``ground_truth.npz`` (the 3-D joints per camera and frame, for scoring only).

Confidences are realistic: a detector is less sure where it is wrong, so each score falls with the
joint's actual pixel error ``e``: ``0.35 + 0.6 exp(-e^2 / (2 s^2))`` with ``s = 2.5 sigma + 0.5`` px,
plus uniform jitter of +-0.03, clipped to ``[0.15, 0.99]`` (every observed joint stays above the
default missing threshold 0.1, so a reconstruction of the export sees the same joints as one of the
shard).

``overwrite`` replaces only an earlier export, and only the files an export writes: ``out`` must hold a
``project.toml`` whose ``source`` says ``gttdata export of ...``, and the files removed are those the
project file names (calibration, ground truth, each camera's detections and timestamps) plus
``project.toml`` itself. Anything else in ``out`` stays. ``out`` may never be, hold or sit inside the
data being exported (``protect``).
"""

from __future__ import annotations

import os
import shutil
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from gttdata.calibration import save_calibration
from gttdata.cameras import Camera, CameraRig
from gttdata.capture.sample import CaptureSample
from gttdata.detectors import Keypoints2D, write_keypoints
from gttdata.errors import GttDataError, OutputError
from gttdata.fileio import fsync_dir, write_error

__all__ = ["EXPORT_FORMATS", "camera_rig_of", "export_capture", "realistic_confidence"]

#: Detector layouts ``export_capture`` writes.
EXPORT_FORMATS: tuple[str, ...] = ("openpose", "dlc")


def realistic_confidence(sample: CaptureSample, rng: np.random.Generator) -> np.ndarray:
    """Detector-like confidence of every joint, shape ``(N, J)`` (NaN where missing); see module docstring."""
    err = np.linalg.norm(sample.keypoints_px.astype(np.float64) - sample.keypoints_gt_px, axis=-1)
    sigma = float(sample.meta.get("capture", {}).get("sigma_px", 2.0) or 0.0)
    s = 2.5 * sigma + 0.5
    c = 0.35 + 0.6 * np.exp(-0.5 * (err / s) ** 2) + rng.uniform(-0.03, 0.03, size=err.shape)
    return np.where(sample.visible, np.clip(c, 0.15, 0.99), np.nan)


def camera_rig_of(sample: CaptureSample) -> CameraRig:
    """The capture's cameras as a rig (``cam_<v>``), with the distortion it was simulated with.

    Raises:
        GttDataError: When a camera's pose changes between its images (a perturbed-camera variant has
            no single calibration).
    """
    dist = sample.meta.get("dist") or [[0.0] * 5] * sample.n_cameras
    cams = []
    for v in range(sample.n_cameras):
        idx = np.flatnonzero(sample.cam_id == v)
        if idx.size == 0:
            raise GttDataError(f"sample {sample.name!r}: camera {v} took no image; nothing to calibrate")
        K, T = sample.K[idx], sample.cam_from_world[idx]
        if np.abs(K - K[0]).max() > 0 or np.abs(T - T[0]).max() > 0:
            raise GttDataError(
                f"sample {sample.name!r}, variant {sample.variant!r}: camera {v} moves between images; "
                "export the 'orig' variant"
            )
        w, h = (int(x) for x in sample.image_size[v])
        size = (w, h)
        cams.append(
            Camera(K=K[0], cam_from_world=T[0], image_size=size, name=f"cam_{v}", dist=tuple(dist[v]))
        )
    return CameraRig(tuple(cams))


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


_EXPORT_SOURCE = "gttdata export of "
_FIXED_FILES = ("calibration.toml", "ground_truth.npz")


def _check_apart(out: Path, protect: Sequence[str | Path]) -> None:
    """Refuse an ``out`` that is, holds or sits inside a protected path (the data being exported)."""
    o = out.resolve()
    for p in protect:
        q = Path(p).resolve()
        if o == q or o in q.parents or q in o.parents:
            how = "is" if o == q else ("holds" if o in q.parents else "sits inside")
            raise OutputError(
                f"{out}: --out {how} the data being exported ({p}); choose a folder apart from it"
            )


def _plain_name(out: Path, name: object) -> str:
    if not isinstance(name, str) or not name or "/" in name or "\\" in name or name in (".", ".."):
        raise OutputError(
            f"{out / 'project.toml'}: expected file names inside the export, found {name!r}; "
            "refusing to delete anything"
        )
    return name


def _remove_previous_export(out: Path) -> None:
    """Remove what an earlier ``gttdata export`` wrote in ``out``, and nothing else.

    Raises:
        OutputError: ``out`` holds no earlier export (no ``project.toml`` naming ``gttdata export``).
    """
    project = out / "project.toml"
    try:
        data = tomllib.loads(project.read_text(encoding="utf-8"))
    except (OSError, ValueError, UnicodeDecodeError):
        data = None
    source = data.get("source") if isinstance(data, dict) else None
    cameras = data.get("cameras") if isinstance(data, dict) else None
    if not (isinstance(source, str) and source.startswith(_EXPORT_SOURCE) and isinstance(cameras, list)):
        found = "no project.toml" if not project.is_file() else f"a project.toml with source {source!r}"
        raise OutputError(
            f"{out}: --overwrite replaces only an earlier gttdata export (project.toml with source "
            f"'{_EXPORT_SOURCE}...'), found {found}; nothing deleted, choose an empty or new --out"
        )
    names = list(_FIXED_FILES)
    for cam in cameras:
        if not isinstance(cam, dict):
            raise OutputError(f"{project}: cameras: expected tables, found {cam!r}; nothing deleted")
        names += [_plain_name(out, cam.get(k)) for k in ("keypoints", "timestamps") if k in cam]
    try:
        for name in names:
            p = out / name
            if p.is_dir() and not p.is_symlink():  # OpenPose: one JSON file per frame, written by us
                for f in p.glob("*_keypoints.json"):
                    f.unlink()
                if not any(p.iterdir()):
                    p.rmdir()
            else:
                p.unlink(missing_ok=True)
        project.unlink()
    except OSError as exc:
        from gttdata.fileio import write_error

        raise write_error(out, exc) from exc


def _every_frame_time(frame: np.ndarray, time_s: np.ndarray) -> np.ndarray:
    """The time of every frame ``0 .. frame[-1]`` of a camera, shape ``(frame[-1] + 1,)``, seconds.

    A timestamp file has one row per video frame (row k is frame k), but a capture holds only the frames
    it kept: a camera started before the capture (frames before the first kept one) and dropped frames
    leave gaps. Kept frames keep their times; gaps are filled on the camera's line ``t = a + b k`` fitted
    to its kept frames (exact for a camera without jitter).

    Args:
        frame: Kept frame numbers, shape ``(F,)``, increasing.
        time_s: Their times, shape ``(F,)``.
    """
    k = np.arange(int(frame[-1]) + 1)
    if frame.shape[0] > 1:
        b, a = np.polyfit(frame.astype(np.float64), time_s, 1)
    else:
        b, a = 1.0, float(time_s[0]) - float(frame[0])
    t = a + b * k
    t[frame] = time_s
    inside = (k > frame[0]) & (k < frame[-1])
    t[inside] = np.interp(k[inside], frame, time_s)
    return t


def export_capture(
    sample: CaptureSample,
    out: str | Path,
    *,
    fmt: str = "openpose",
    units: str = "m",
    shared_clock: bool = False,
    seed: int = 0,
    dlc_suffix: str = ".csv",
    overwrite: bool = False,
    protect: Sequence[str | Path] = (),
) -> Path:
    """Write ``sample`` as detector files plus calibration, timestamps and a project file.

    Args:
        sample: The capture (metres, true time order).
        out: Output folder (created).
        fmt: One of :data:`EXPORT_FORMATS`.
        units: Length unit of the calibration's translations (``m``, ``cm`` or ``mm``).
        shared_clock: Timestamps on the capture's common clock (a synchronized rig) instead of each
            camera's own clock.
        seed: Seed of the confidence jitter.
        dlc_suffix: ``.csv`` or ``.h5`` for DeepLabCut files.
        overwrite: Replace an earlier export in ``out`` (else a non-empty ``out`` is an error): only
            the files that export wrote are removed, and only when ``out`` holds one.
        protect: Paths ``out`` must not equal, contain or sit inside (the dataset or shard exported).

    Returns:
        The project file path.

    Raises:
        GttDataError: ``out`` is not empty and ``overwrite`` is False.
        OutputError: ``out`` overlaps a protected path, or ``overwrite`` finds something other than an
            earlier export there (nothing is deleted); or a write failed (full disk...): one line naming
            ``out``, and nothing of the new export is left in it.
    """
    if fmt not in EXPORT_FORMATS:
        raise ValueError(f"format must be one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}")
    out = Path(out)
    _check_apart(out, protect)
    if out.exists() and any(out.iterdir()):
        if not overwrite:
            raise GttDataError(f"{out}: output folder is not empty; pass --overwrite to replace its export")
    rig = camera_rig_of(sample)
    # The export is written whole into a hidden sibling folder first: a failed write (a full disk)
    # leaves nothing of it, and an earlier export being replaced is removed only once it succeeded.
    work = out.with_name(f".{out.name}.{os.getpid()}.tmp")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir()
        _write_export(
            sample,
            rig,
            work,
            fmt=fmt,
            units=units,
            shared_clock=shared_clock,
            seed=seed,
            dlc_suffix=dlc_suffix,
        )
        _fsync_tree(work)
        if out.exists() and any(out.iterdir()):
            _remove_previous_export(out)  # overwrite (checked above): only what that export wrote
        _move_into_place(work, out)
    except OSError as exc:
        raise write_error(out, exc) from exc
    except OutputError as exc:  # an inner atomic write names its file inside the hidden folder
        raise OutputError(str(exc).replace(str(work), str(out))) from exc
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out / "project.toml"


def _fsync_tree(folder: Path) -> None:
    """Flush every file under ``folder`` to disk (the renames that publish them must not outrun them)."""
    for path in sorted(folder.rglob("*")):
        if path.is_file():
            with open(path, "rb+") as fh:
                os.fsync(fh.fileno())


def _move_into_place(work: Path, out: Path) -> None:
    """Publish the finished export ``work`` as ``out`` (renames only: they need no disk space).

    A new ``out`` is one rename. Into an existing folder, which may hold other files, each entry is
    renamed in, ``project.toml`` last.

    Raises:
        OutputError: ``out`` holds a file of the same name that no earlier export wrote (nothing moved).
    """
    if not out.exists():
        os.replace(work, out)
    else:
        entries = sorted(work.iterdir(), key=lambda p: (p.name == "project.toml", p.name))
        taken = [p.name for p in entries if (out / p.name).exists() or (out / p.name).is_symlink()]
        if taken:
            raise OutputError(
                f"{out}: holds {', '.join(taken)}, which no earlier gttdata export wrote there; "
                "nothing of the new export was moved in, choose an empty or new --out"
            )
        for p in entries:
            os.replace(p, out / p.name)
    fsync_dir(out)
    fsync_dir(out.parent)


def _write_export(
    sample: CaptureSample,
    rig: CameraRig,
    out: Path,
    *,
    fmt: str,
    units: str,
    shared_clock: bool,
    seed: int,
    dlc_suffix: str,
) -> None:
    """Write every file of the export into the existing, empty folder ``out``."""
    save_calibration(rig, out / "calibration.toml", units=units)
    conf = realistic_confidence(sample, np.random.default_rng(seed))
    names = sample.skeleton.joint_names
    cameras, gt_rows = [], {}
    for v, cam in enumerate(rig.cameras):
        idx = np.flatnonzero(sample.cam_id == v)
        idx = idx[np.argsort(sample.stream_index[idx], kind="stable")]
        frame = sample.stream_index[idx].astype(np.int64)
        kp = Keypoints2D(
            xy=np.where(sample.visible[idx][..., None], sample.keypoints_px[idx].astype(np.float64), np.nan),
            score=conf[idx],
            frame=frame,
            joint_names=names,
            source=cam.name,
            fmt=fmt,
        )
        target = out / cam.name if fmt == "openpose" else out / f"{cam.name}{dlc_suffix}"
        write_keypoints(kp, target, fmt)
        t = _every_frame_time(frame, sample.timestamp_s[idx])
        t = t if shared_clock else t - t[0]
        ts_path = out / f"{cam.name}_timestamps.csv"
        _write_text(ts_path, "".join(f"frame,{x:.9f}\n" for x in t))
        fps = sample.meta.get("capture", {}).get("fps_hz", [None] * sample.n_cameras)[v]
        entry: dict[str, str | float] = {
            "name": cam.name,
            "keypoints": target.name,
            "timestamps": ts_path.name,
        }
        if fps:
            entry["nominal_fps"] = float(fps)
        cameras.append(entry)
        gt_rows[cam.name] = (frame, sample.points3d[idx])
    gt_arrays: dict[str, Any] = {f"{k}_frame": f for k, (f, _) in gt_rows.items()}
    gt_arrays.update({f"{k}_points3d": x for k, (_, x) in gt_rows.items()})
    np.savez_compressed(out / "ground_truth.npz", **gt_arrays)
    project = {
        "calibration": "calibration.toml",
        "calibration_units": units,
        "clock": "shared" if shared_clock else "per-camera",
        "min_confidence": 0.1,
        "skeleton": "cmu31" if sample.skeleton.name == "cmu31" else sample.skeleton.to_dict(),
        "ground_truth": "ground_truth.npz",
        "source": f"gttdata export of {sample.name} ({sample.motion_name}), format {fmt}",
        "cameras": cameras,
    }
    _write_text(out / "project.toml", tomli_w.dumps(project))
