"""The recording pipeline as a library: what ``gttnet reconstruct`` and ``gttnet sync`` call for a recording.

A recording is named by a project file, a Pose2Sim / anipose folder (:mod:`gttdata.recording_folders`) or
``--calibration`` with ``--keypoints``; :func:`recording_spec` turns any of them into a
:class:`~gttdata.recording.RecordingSpec`, :func:`load_view` reads it into solver inputs, and
:func:`write_motion_outputs` writes the time-ordered result as OpenSim-ready files:

* **TRC** (OpenSim / Pose2Sim marker trajectories): one row per frame on a uniform clock, by default the
  fastest camera's rate, interpolated from the recovered (or shared-clock) times of every image;
  ``DataRate`` and ``CameraRate`` are that rate and ``NumFrames`` the row count. Y up by default as in
  OpenSim and Pose2Sim (``up="y"``: TRC X, Y, Z = world y, z, x, Pose2Sim's ``zup2yup``), or the world's
  Z up (``up="z"``). Markers carry Pose2Sim's names (:func:`gttdata.skeletons_detectors.trc_marker_names`).
* A low-pass of the uniform result (:func:`filter_motion`): a zero-phase Butterworth (cut-off in Hz), a
  Gaussian (sigma in frames) or a median (window in frames), run on each gap-free stretch of each joint.

``fps`` values (:func:`parse_fps`) are one per camera, in the forms docs/CLI.md lists.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path
from typing import Any

import numpy as np

from gttdata.errors import KeypointFormatError

__all__ = [
    "FILTERS",
    "UP_AXES",
    "apply_fps",
    "export_keypoints_on_clock",
    "export_retimed_keypoints",
    "filter_motion",
    "load_view",
    "marker_names",
    "parse_fps",
    "parse_filter",
    "plain",
    "recording_spec",
    "to_trc_frame",
    "timing_options",
    "uniform_motion",
    "write_outputs",
]

log = logging.getLogger(__name__)

#: ``--up`` choices of TRC output.
UP_AXES: tuple[str, ...] = ("y", "z")

#: ``--filter`` kinds and the unit of their parameter.
FILTERS: dict[str, str] = {
    "butterworth": "cut-off, Hz",
    "gaussian": "sigma, frames",
    "median": "window, frames",
}


def parse_fps(
    values: str | tuple[str, ...] | list[str] | None,
) -> float | list[float] | dict[str, float] | None:
    """Frame rates from ``--fps``: one for every camera, one per camera in order, or by camera.

    Accepted: ``"30"``; ``"25,30,60"`` or the option repeated (``("25", "30", "60")``); ``"cam_0=25,cam_2=60"``
    or ``"0=25,2=60"`` (by camera name or index). Returns a float, a list (camera order) or a dict (keys as
    written), or None when not given.

    Raises:
        KeypointFormatError: Not a number, a list of numbers or ``camera=rate`` pairs, or a rate <= 0.

    Example:
        >>> parse_fps("25,30"), parse_fps(("25", "30")), parse_fps("cam_1=60"), parse_fps("30")
        ([25.0, 30.0], [25.0, 30.0], {'cam_1': 60.0}, 30.0)
    """
    if values is None or (not isinstance(values, str) and not values):
        return None
    text = values if isinstance(values, str) else ",".join(values)
    items = [s.strip() for s in text.split(",") if s.strip()]
    try:
        if items and all("=" in s for s in items):
            out: Any = {k.strip(): float(v) for k, v in (s.split("=", 1) for s in items)}
            rates = list(out.values())
        else:
            rates = [float(s) for s in items]
            out = rates[0] if len(rates) == 1 else rates
    except ValueError:
        rates = []
    if not rates or not all(np.isfinite(r) and r > 0 for r in rates):
        raise KeypointFormatError(
            f"--fps: expected Hz as '30', '25,30,60' (one per camera, in order) or 'cam_0=25,cam_2=60', got {text!r}"
        )
    return out


def apply_fps(spec, fps: float | list[float] | dict[str, float] | None):
    """``spec`` with the cameras' rates replaced by ``fps`` (see :func:`parse_fps`); None keeps them.

    Raises:
        KeypointFormatError: A list whose length is not the camera count, or a name or index no camera has.
    """
    if fps is None:
        return spec
    cams = list(spec.cameras)
    names = [c.name for c in cams]
    if isinstance(fps, float):
        rates: dict[int, float] = dict.fromkeys(range(len(cams)), fps)
    elif isinstance(fps, list):
        if len(fps) != len(cams):
            raise KeypointFormatError(
                f"--fps: give one rate for all cameras or one per camera ({len(cams)}: {', '.join(names)}), "
                f"got {len(fps)}"
            )
        rates = dict(enumerate(fps))
    else:
        rates = {}
        for key, r in fps.items():
            if key in names:
                rates[names.index(key)] = r
            elif key.isdigit() and int(key) < len(cams):
                rates[int(key)] = r
            else:
                raise KeypointFormatError(f"--fps: no camera {key!r}; the cameras are {', '.join(names)}")
    for i, r in rates.items():
        cams[i] = dataclasses.replace(cams[i], fps=float(r))
    return dataclasses.replace(spec, cameras=tuple(cams))


def recording_spec(
    inputs: tuple[str, ...] | list[str],
    *,
    calibration: str | None = None,
    keypoints: tuple[str, ...] = (),
    fps: str | tuple[str, ...] | None = None,
    timestamps: tuple[str, ...] = (),
    clock: str = "per-camera",
    calibration_units: str | None = None,
    min_confidence: float | None = None,
    skeleton: str | None = None,
):
    """The recording named by the inputs, or None when they name a stored capture (shard, .mat, .json).

    A recording is ``--calibration`` with ``--keypoints`` (or keypoint paths as inputs), one project file
    (``.toml``/``.yaml``), or one Pose2Sim / anipose folder.

    Raises:
        KeypointFormatError: ``--keypoints`` without ``--calibration``, numbers given as inputs (``--fps 30
            30`` instead of ``--fps 30,30``), or a malformed source.
    """
    from gttdata.recording import load_project
    from gttdata.recording_folders import is_recording_folder, spec_from_folder
    from gttnet.io.recording_input import spec_from_options

    stray = [p for p in inputs if _is_number(p) and not Path(p).exists()]
    if stray:
        raise KeypointFormatError(
            f"inputs {', '.join(stray)} look like frame rates: give one rate per camera as --fps 25,30,60 "
            "(or --fps 25 --fps 30 --fps 60)"
        )
    one = len(inputs) == 1 and calibration is None and not keypoints
    if one and Path(inputs[0]).suffix.lower() in (".toml", ".yaml", ".yml") and Path(inputs[0]).is_file():
        spec = load_project(inputs[0])
    elif one and is_recording_folder(inputs[0]):
        spec = spec_from_folder(inputs[0])
    elif calibration is not None or keypoints:
        if calibration is None:
            raise KeypointFormatError("--keypoints needs --calibration (or give a project file or a folder)")
        spec = spec_from_options(
            calibration, list(keypoints) + list(inputs), timestamps=tuple(timestamps), clock=clock
        )
    else:
        return None
    spec = apply_fps(spec, parse_fps(fps))
    changes: dict[str, Any] = {}
    if calibration_units is not None:
        changes["calibration_units"] = calibration_units
    if min_confidence is not None:
        changes["min_confidence"] = float(min_confidence)
    if skeleton is not None:
        changes["skeleton"] = skeleton
    return dataclasses.replace(spec, **changes) if changes else spec


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def choose_subjects(recording, spec, n_subjects: int = 1) -> list:
    """The recording once per subject, each camera's detections those of that person.

    Where an OpenPose camera folder holds several people in a frame (its keypoints' ``crowd``, read once
    with them), people are associated across the
    unsynchronized cameras and through time (:func:`gttnet.association.associate`): the subjects are the
    people most cameras agree on, so a bystander seen by one camera for a few frames never takes over.
    Cameras whose sources hold one person per frame keep it as a candidate. A recording with one person
    per frame everywhere is returned as it is (``n_subjects`` must then be 1).

    Args:
        recording: The loaded :class:`gttdata.recording.Recording`.
        spec: Its spec (named in messages).
        n_subjects: How many people to return, most supported first (stable ids 0, 1, ...).

    Returns:
        Up to ``n_subjects`` recordings.

    Raises:
        KeypointFormatError: Fewer people than ``n_subjects`` are seen by two or more cameras.
    """
    from gttnet.association import CameraPeople, associate

    crowds = [kp.crowd for kp in recording.keypoints]
    if all(c is None for c in crowds):
        if n_subjects > 1:
            raise KeypointFormatError(
                f"{spec.calibration}: --subjects {n_subjects}: every camera's keypoints hold one person per frame"
            )
        return [recording]
    tables = []
    for kp, people in zip(recording.keypoints, crowds, strict=True):
        frame, xy, score = people if people is not None else (kp.frame, kp.xy, kp.score)
        tables.append(CameraPeople(frame, xy, np.nan_to_num(score, nan=0.0)))
    fps = [float(f) if np.isfinite(f) else 30.0 for f in recording.fps]
    subjects = associate(tables, list(recording.rig.cameras), fps, n_subjects=n_subjects)
    if len(subjects) < n_subjects:
        raise KeypointFormatError(
            f"{spec.calibration}: --subjects {n_subjects}: found {len(subjects)} people seen by two or more cameras"
        )
    log.info(
        "people across cameras: %s",
        "; ".join(
            f"subject {k}: {s.support} detections in {s.n_cameras} cameras" for k, s in enumerate(subjects)
        ),
    )
    out = []
    for s in subjects:
        kps, times = [], []
        for v, (kp, t, rows) in enumerate(zip(recording.keypoints, tables, s.detections, strict=True)):
            score = np.where(t.score[rows] > 0, t.score[rows], np.nan)
            kps.append(
                dataclasses.replace(kp, xy=t.keypoints_px[rows], score=score, frame=t.frame[rows], crowd=None)
            )
            st = recording.stream_time_s[v]  # a row's time follows its frame number
            times.append(None if st is None else st[np.searchsorted(kp.frame, t.frame[rows])])
        out.append(dataclasses.replace(recording, keypoints=tuple(kps), stream_time_s=tuple(times)))
    return out


def load_views(
    spec,
    sequencing: str | None,
    *,
    min_confidence=None,
    weights: bool = True,
    seed: int = 0,
    n_subjects: int = 1,
) -> list[tuple[Any, Any, Any]]:
    """``[(recording, view, ground truth or None), ...]``, one per subject; the calibration's warnings are logged.

    The files are read and the people associated once: with several people in the keypoint files, the
    views are those of the ``n_subjects`` best-supported subjects, in order (:func:`choose_subjects`).
    """
    from gttdata.recording import Recording, ground_truth_for

    out = []
    for rec in choose_subjects(Recording.load(spec), spec, n_subjects):
        view = rec.view(sequencing, min_confidence=min_confidence, weights=weights, seed=seed)
        out.append(
            (rec, view, None if spec.ground_truth is None else ground_truth_for(view, spec.ground_truth))
        )
    return out


def load_view(spec, sequencing: str | None, *, min_confidence=None, weights: bool = True, seed: int = 0):
    """``(recording, view, ground truth or None)`` of a spec's best-supported subject (:func:`load_views`)."""
    return load_views(spec, sequencing, min_confidence=min_confidence, weights=weights, seed=seed)[0]


def to_trc_frame(points: np.ndarray, up: str) -> np.ndarray:
    """World points (Z up) in a TRC's frame: ``up="y"`` gives X, Y, Z = world y, z, x; ``"z"`` keeps them.

    Args:
        points: Metres, shape ``(..., 3)``, world Z up.
        up: One of :data:`UP_AXES`.

    Example:
        >>> to_trc_frame(np.array([1.0, 2.0, 3.0]), "y").tolist()
        [2.0, 3.0, 1.0]
    """
    if up not in UP_AXES:
        raise ValueError(f"up must be one of {', '.join(UP_AXES)}, got {up!r}")
    return points[..., [1, 2, 0]] if up == "y" else points


def uniform_motion(table, rate_hz: float | None, fps: np.ndarray):
    """A timed table on a uniform clock: ``rate_hz``, else the fastest camera's rate, else its own rate.

    An untimed table (no clock: per-camera times without recovery) is returned as is.
    """
    from gttnet.io.motion_files import resample

    if not table.timed:
        return table
    if rate_hz is None:
        finite = np.asarray(fps, dtype=np.float64)
        finite = finite[np.isfinite(finite) & (finite > 0)]
        rate_hz = float(finite.max()) if finite.size else float(table.rate_hz)
    return resample(table, rate_hz)


def parse_filter(text: str | None) -> tuple[str, float] | None:
    """``"butterworth:6"`` -> ``("butterworth", 6.0)`` (see :data:`FILTERS`); None passes through.

    Raises:
        KeypointFormatError: An unknown kind or a parameter that is not a positive number.
    """
    if text is None:
        return None
    kind, _, value = text.partition(":")
    kind = kind.strip().lower()
    try:
        v = float(value)
    except ValueError:
        v = -1.0
    if kind not in FILTERS or not v > 0:
        raise KeypointFormatError(
            "--filter: expected KIND:VALUE with KIND one of "
            + ", ".join(f"{k} ({u})" for k, u in FILTERS.items())
            + f", got {text!r}"
        )
    return kind, v


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """``[start, stop)`` of each stretch of True."""
    d = np.diff(np.concatenate([[0], ok.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def filter_motion(table, kind: str, value: float):
    """Low-pass of a uniform table's joints, each gap-free stretch on its own (NaN gaps stay NaN).

    ``butterworth``: 4th-order zero-phase (``scipy.signal.filtfilt``) with cut-off ``value`` Hz, which must
    be below half the rate; stretches too short for its padding are left as they are. ``gaussian``: sigma
    ``value`` frames (``scipy.ndimage.gaussian_filter1d``, edges mirrored). ``median``: window ``value``
    frames, rounded up to odd (``scipy.signal.medfilt``-like, edges shortened).

    Raises:
        ValueError: A table that is not on a uniform clock, or a cut-off at or above the Nyquist rate.
    """
    from scipy import ndimage, signal

    t = table.time_s
    if t.shape[0] > 2 and (not table.timed or np.ptp(np.diff(t)) > 1e-6 * max(np.mean(np.diff(t)), 1e-12)):
        raise ValueError("filtering needs a uniform clock: times from a shared clock or recovered clocks")
    rate = float(table.rate_hz)
    X = np.array(table.points3d, dtype=np.float64)
    if kind == "butterworth":
        if not value < rate / 2:
            raise ValueError(f"butterworth cut-off {value} Hz must be below half the rate ({rate / 2:g} Hz)")
        b, a = signal.butter(4, value / (rate / 2))
        pad = 3 * max(len(a), len(b))
    for j in range(X.shape[1]):
        ok = np.all(np.isfinite(X[:, j]), axis=1)
        for s, e in _runs(ok):
            seg = X[s:e, j]
            if kind == "butterworth":
                if e - s > pad:
                    X[s:e, j] = signal.filtfilt(b, a, seg, axis=0)
            elif kind == "gaussian":
                X[s:e, j] = ndimage.gaussian_filter1d(seg, value, axis=0, mode="mirror")
            else:
                w = int(np.ceil(value)) | 1
                X[s:e, j] = ndimage.median_filter(seg, size=(w, 1), mode="nearest")
    return dataclasses.replace(table, points3d=X)


def write_outputs(rec, view, outs, resample_hz, *, image_index, source, recording_json, trc):
    """Write every output of a reconstruction ``rec`` of ``view``; the suffix picks the layout.

    ``.trc``/``.c3d``: OpenSim-ready (:func:`uniform_motion`, then ``trc["filter"]`` (kind, value) or None,
    marker names ``trc["names"]``, ``.trc`` in ``trc["up"]``); ``.csv``: one row per image in time order
    (resampled onto ``resample_hz`` when given); ``.h5``/``.npz``: the reconstruction with the recording's
    per-image arrays. Parent folders are created.
    """
    import json

    from gttnet.io.motion_files import MOTION_SUFFIXES, motion_table, resample, write_motion
    from gttnet.io.output import write_reconstruction

    table = motion_table(rec, view)
    time_s = np.full(rec.n_images, np.nan)
    if table.timed:
        time_s[table.row] = table.time_s
    order_rows = table.row.copy()
    per_image = resample(table, resample_hz) if resample_hz is not None else table
    opensim = None
    for out in outs:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        suffix = Path(out).suffix.lower()
        if suffix in (".trc", ".c3d"):
            if opensim is None:
                if not table.timed:
                    log.warning(
                        "%s: no clock (per-camera times and a method that recovers none): one row per image "
                        "at ranked times, not a uniform rate; --method sync (or auto) recovers the clocks",
                        out,
                    )
                opensim = uniform_motion(table, resample_hz, view.fps)
                if trc["filter"] is not None:
                    opensim = filter_motion(opensim, *trc["filter"])
                if trc["names"] is not None:
                    opensim = dataclasses.replace(opensim, joint_names=trc["names"])
            up = trc["up"] if suffix == ".trc" else "z"
            write_motion(dataclasses.replace(opensim, points3d=to_trc_frame(opensim.points3d, up)), out)
        elif suffix in MOTION_SUFFIXES:
            write_motion(per_image, out)
        else:
            write_reconstruction(
                rec,
                out,
                image_index=image_index,
                source=source,
                extra={
                    "cam_id": view.observations.cam_id.astype(np.int64),
                    "frame": np.asarray(view.frame, dtype=np.int64),
                    "time_s": time_s,
                    "time_order": order_rows,
                },
                extra_attrs={
                    "camera_names": json.dumps(list(view.camera_names)),
                    "recording": recording_json,
                },
            )


def timing_options(method: str, view) -> dict:
    """Known per-camera timing for methods that take it (clock recovery: ``frame_times_s``, ``fps``)."""
    import inspect

    import numpy as np

    from gttnet.methods import method_spec

    params = inspect.signature(method_spec(method).fn).parameters
    obs, out = view.observations, {}
    if "frame_times_s" in params and obs.stream_time_s is not None:
        out["frame_times_s"] = np.asarray(obs.stream_time_s, dtype=np.float64)
    fps = np.asarray(view.fps, dtype=np.float64)
    if "fps" in params and fps.size and np.all(np.isfinite(fps)):
        out["fps"] = fps.tolist()
    return out


def marker_names(skeleton, obs) -> tuple[str, ...]:
    """Pose2Sim's marker names of the recording's skeleton (or the observations')."""
    from gttdata.skeletons_detectors import trc_marker_names

    return trc_marker_names(skeleton if skeleton is not None else obs.skeleton)


def export_retimed_keypoints(
    recording, view, time_s: np.ndarray, rate_hz: float, out_dir: str | Path
) -> Path:
    """Each camera's detections re-timed onto one clock, as OpenPose JSON folders (``<camera>_json``).

    Pose2Sim's or anipose's triangulation, which needs synchronized frames, can run on them. Frame ``k``
    of every folder is at ``t0 + k / rate_hz`` on the common clock (``t0`` the first image's time). Each
    joint's pixel and score are linear in time between the two detections of its camera around that
    instant; a joint is missing (``0, 0, 0``) where its camera did not detect it within 2.5 of its frame
    periods on each side. Pixels are the detector's own (lens distortion kept): the calibration still
    applies to them.

    Args:
        recording: The :class:`~gttdata.recording.Recording` that ``view`` was made from.
        view: The view reconstructed.
        time_s: Each view image's time on the common clock (recovered or shared), shape ``(N,)``.
        rate_hz: Rate of the common frames, Hz.
        out_dir: Folder to write (one subfolder per camera).

    Returns:
        ``out_dir``.
    """
    from gttdata.detectors import Keypoints2D
    from gttdata.detectors.openpose import write_openpose

    out = Path(out_dir)
    t = np.asarray(time_s, dtype=np.float64)
    t0, t1 = float(np.nanmin(t)), float(np.nanmax(t))
    grid = t0 + np.arange(int(np.floor((t1 - t0) * rate_hz + 1e-9)) + 1) / rate_hz
    cam_id = view.observations.cam_id
    for v, kp in enumerate(recording.keypoints):
        rows = np.flatnonzero(cam_id == v)
        rows = rows[np.argsort(t[rows], kind="stable")]
        pos = np.searchsorted(kp.frame, view.frame[rows])
        tv, xy, sc = t[rows], kp.xy[pos], kp.score[pos]
        rate_v = float(view.fps[v]) if np.isfinite(view.fps[v]) else (rows.size - 1) / max(np.ptp(tv), 1e-9)
        gxy = np.full((grid.shape[0], kp.n_joints, 2), np.nan)
        gsc = np.full((grid.shape[0], kp.n_joints), np.nan)
        for j in range(kp.n_joints):
            ok = np.isfinite(sc[:, j]) & np.all(np.isfinite(xy[:, j]), axis=1)
            if ok.sum() < 2:
                continue
            ft = tv[ok]
            k = np.clip(np.searchsorted(ft, grid), 1, ft.size - 1)
            near = (grid >= ft[0]) & (grid <= ft[-1]) & (ft[k] - ft[k - 1] <= 2.5 / rate_v)
            for a in range(2):
                gxy[near, j, a] = np.interp(grid[near], ft, xy[ok, j, a])
            gsc[near, j] = np.interp(grid[near], ft, sc[ok, j])
        name = view.camera_names[v]
        retimed = Keypoints2D(
            xy=gxy, score=gsc, frame=np.arange(grid.shape[0]), joint_names=kp.joint_names, source=name
        )
        write_openpose(retimed, out / f"{name}_json", prefix=name)
    return out


def export_keypoints_on_clock(recording, rec, view, folder, *, rate_hz=None, overwrite: bool = False) -> Path:
    """``--export-keypoints``: :func:`export_retimed_keypoints` at the reconstruction's times.

    The rate is ``rate_hz``, else the fastest camera's, else the result's own.

    Raises:
        GttNetError: Not a recording, a result without times, or a non-empty ``folder`` without ``overwrite``.
    """
    from gttnet.errors import GttNetError
    from gttnet.io.motion_files import motion_table

    if recording is None:
        raise GttNetError("--export-keypoints applies to recordings (2-D keypoint files)")
    if Path(folder).exists() and any(Path(folder).iterdir()) and not overwrite:
        raise GttNetError(f"{folder}: exists and is not empty; pass --overwrite to write into it")
    table = motion_table(rec, view)
    if not table.timed:
        raise GttNetError(
            "--export-keypoints needs times: timestamps on a shared clock or a method that recovers clocks (sync)"
        )
    t = np.empty(rec.n_images)
    t[table.row] = table.time_s
    fps = np.asarray(view.fps, dtype=np.float64)
    rate = rate_hz or (float(np.nanmax(fps)) if np.any(np.isfinite(fps)) else table.rate_hz)
    return export_retimed_keypoints(recording, view, t, rate, folder)


def plain(value) -> str:
    """A summary value for people: ``cam_0:0.1,cam_1:-0.03`` for a dict, ``1,4`` for a list.

    Example:
        >>> plain({"cam_0": 0.0, "cam_1": [1, 2]})
        'cam_0:0.0,cam_1:1,2'
    """
    if isinstance(value, dict):
        return ",".join(f"{k}:{plain(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return ",".join(plain(v) for v in value)
    return str(value)
