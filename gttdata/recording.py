"""A real recording: a calibration, one 2-D keypoint source per camera, and what is known of each camera's timing.

A recording becomes solver :class:`~gttdata.capture.views.Observations` through
:meth:`Recording.view`. Timing per camera comes from a frame rate (``--fps``, frame ``k`` at
``k / fps``) or from a per-frame timestamp CSV as ``ffprobe`` writes it. Each camera's times are on
its own clock (offsets between cameras unknown), which gives ``partial`` sequencing with
``stream_time_s`` filled in: the input clock recovery needs. With ``clock = "shared"`` (a hardware-
synchronized rig whose timestamps share one clock) the view is ``full``.

A project file (TOML or YAML) makes a run repeatable::

    calibration = "calibration.toml"     # or intri.yml; relative paths are from the project file
    calibration_units = "mm"             # optional: m, cm, mm (default: the file's, else detected)
    clock = "per-camera"                 # or "shared"
    min_confidence = 0.1                 # optional: detections below this are missing
    skeleton = "cmu31"                   # optional: the keypoints' skeleton by name
    [[cameras]]
    name = "cam_0"                       # a camera of the calibration
    keypoints = "cam_0"                  # OpenPose folder, DeepLabCut .csv/.h5, SLEAP .slp, COCO .json
    timestamps = "cam_0_timestamps.csv"  # or fps = 30.0
"""

from __future__ import annotations

import csv
import dataclasses
import io
import logging
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gttdata.calibration import load_calibration, undistort_points
from gttdata.cameras import Camera, CameraRig
from gttdata.capture.views import SEQUENCING, Observations
from gttdata.detectors import Keypoints2D, candidate_sets, read_keypoints
from gttdata.errors import CalibrationError, KeypointFormatError, NoDetectionsError
from gttdata.skeleton import Skeleton, cmu31

__all__ = [
    "CLOCKS",
    "CameraInput",
    "Recording",
    "RecordingSpec",
    "RecordingView",
    "load_project",
    "ground_truth_for",
    "read_timestamps_csv",
]

log = logging.getLogger(__name__)

#: ``per-camera``: each camera's times are on its own clock; ``shared``: all on one clock.
CLOCKS: tuple[str, ...] = ("per-camera", "shared")

#: Column names of a timestamp CSV that hold the frame time in seconds (ffprobe's, then ours).
_TIME_COLUMNS = (
    "best_effort_timestamp_time",
    "pts_time",
    "pkt_pts_time",
    "pkt_dts_time",
    "timestamp_s",
    "time_s",
)


def read_timestamps_csv(path: str | Path) -> np.ndarray:
    """Per-frame times, seconds, of one camera's video, shape ``(F,)`` (row k is frame k).

    Accepts what ``ffprobe -select_streams v:0 -show_entries frame=best_effort_timestamp_time -of csv``
    writes (``frame,0.033367``), the same with ``-of csv=p=0`` (one number per line) or with a header
    line naming the column (``pts_time``, ``best_effort_timestamp_time``, ``timestamp_s``...). Times
    must strictly increase.

    Raises:
        KeypointFormatError: An empty file, a non-numeric time (``N/A``), or times that do not increase.
    """
    path = Path(path)
    rows = [r for r in csv.reader(io.StringIO(path.read_text())) if r and any(c.strip() for c in r)]
    if not rows:
        raise KeypointFormatError(f"{path}: no timestamps in the file")
    col = None
    first = [c.strip() for c in rows[0]]
    if any(c in _TIME_COLUMNS for c in first):
        col = next(i for i, c in enumerate(first) if c in _TIME_COLUMNS)
        rows = rows[1:]
    times = np.empty(len(rows))
    for k, r in enumerate(rows):
        cells = [c.strip() for c in r]
        if col is None:
            cells = [c for c in cells if c not in ("frame", "packet")] or cells
            value = cells[0] if len(cells) == 1 else cells[-1]
        else:
            value = cells[col] if col < len(cells) else ""
        try:
            times[k] = float(value)
        except ValueError:
            line = k + 1 + (col is not None)
            raise KeypointFormatError(
                f"{path}: line {line}: frame time must be a number, found {value!r}"
            ) from None
    if not np.all(np.isfinite(times)):
        raise KeypointFormatError(f"{path}: frame times must be finite")
    bad = np.flatnonzero(np.diff(times) <= 0)
    if bad.size:
        k = int(bad[0])
        raise KeypointFormatError(
            f"{path}: frame times must increase, found {times[k]} then {times[k + 1]} (line {k + 2})"
        )
    return times


@dataclass(frozen=True)
class CameraInput:
    """One camera of a recording: its name in the calibration, its keypoint source and its timing.

    Args:
        name: Camera name, as in the calibration.
        keypoints: OpenPose folder or detector file.
        fps: Frame rate, Hz, or None.
        timestamps: Per-frame timestamp CSV, or None.
    """

    name: str
    keypoints: Path
    fps: float | None = None
    timestamps: Path | None = None


@dataclass(frozen=True)
class RecordingSpec:
    """What to read for a recording (a project file, or the CLI's options).

    Args:
        calibration: Calibration file (``.toml``, ``intri.yml`` or a folder of the EasyMocap pair).
        cameras: The cameras, in any order.
        calibration_units: Unit of the calibration's translations, or None (file's, else detected).
        clock: One of :data:`CLOCKS`.
        keypoint_format: ``"auto"`` or a detector format name.
        min_confidence: Detections with a lower score are missing.
        skeleton: Skeleton name of the keypoints (``"cmu31"``), a skeleton dict, or None (from names).
        ground_truth: ``ground_truth.npz`` of an exported capture (scoring only; never reaches a solver).
    """

    calibration: Path
    cameras: tuple[CameraInput, ...]
    calibration_units: str | None = None
    clock: str = "per-camera"
    keypoint_format: str = "auto"
    min_confidence: float = 0.1
    skeleton: str | dict | None = None
    ground_truth: Path | None = None


def _path(base: Path, value: object, where: str, src: Path) -> Path:
    if not isinstance(value, str) or not value:
        raise KeypointFormatError(f"{src}: field {where!r} must be a path string, found {value!r}")
    p = Path(value).expanduser()
    return p if p.is_absolute() else base / p


def _positive_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and 0 < value < float("inf")


def _choice(path: Path, d: dict, key: str, allowed: tuple[str, ...], default: str | None) -> str | None:
    value = d.get(key, default)
    if value is not None and (not isinstance(value, str) or value not in allowed):
        raise KeypointFormatError(
            f"{path}: field {key!r} must be one of {', '.join(allowed)}, found {value!r}"
        )
    return value


def _project_camera(path: Path, i: int, c: object) -> CameraInput:
    if not isinstance(c, dict) or "name" not in c or "keypoints" not in c:
        raise KeypointFormatError(f"{path}: cameras[{i}] needs fields 'name' and 'keypoints'")
    name = c["name"]
    if isinstance(name, bool) or not isinstance(name, str | int) or name == "":
        raise KeypointFormatError(f"{path}: cameras[{i}].name must be a camera name, found {name!r}")
    fps = c.get("fps")
    if fps is not None and not _positive_number(fps):
        raise KeypointFormatError(f"{path}: cameras[{i}].fps must be a positive number, found {fps!r}")
    ts = c.get("timestamps")
    return CameraInput(
        name=str(name),
        keypoints=_path(path.parent, c["keypoints"], f"cameras[{i}].keypoints", path),
        fps=None if fps is None else float(fps),
        timestamps=None if ts is None else _path(path.parent, ts, f"cameras[{i}].timestamps", path),
    )


def load_project(path: str | Path) -> RecordingSpec:
    """Read a project file (``.toml`` or ``.yaml``/``.yml``, layout in the module docstring).

    YAML project files are read like recipes (:func:`gttdata.recipe.yamlio.load_yaml`): a key written
    twice is refused.

    Raises:
        KeypointFormatError: Unparseable file or a missing/invalid field (named).
    """
    import yaml  # imported on use, not at start-up

    from gttdata.calibration import CALIBRATION_UNITS
    from gttdata.detectors import FORMATS
    from gttdata.recipe.yamlio import load_yaml, yaml_error_line

    path = Path(path)
    try:
        text = path.read_text()
        d = load_yaml(text) if path.suffix.lower() in (".yaml", ".yml") else tomllib.loads(text)
    except yaml.YAMLError as exc:
        raise KeypointFormatError(f"{path}: cannot parse project file: {yaml_error_line(exc)}") from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise KeypointFormatError(f"{path}: cannot parse project file: {exc}") from exc
    if not isinstance(d, dict):
        raise KeypointFormatError(f"{path}: a project file must be a table, found {type(d).__name__}")
    for key in ("calibration", "cameras"):
        if key not in d:
            raise KeypointFormatError(f"{path}: field {key!r} is missing")
    if not isinstance(d["cameras"], list) or not d["cameras"]:
        raise KeypointFormatError(f"{path}: field 'cameras' must be a non-empty list of tables")
    cams = [_project_camera(path, i, c) for i, c in enumerate(d["cameras"])]
    clock = _choice(path, d, "clock", CLOCKS, "per-camera")
    units = _choice(path, d, "calibration_units", tuple(CALIBRATION_UNITS), None)
    fmt = _choice(path, d, "keypoint_format", ("auto", *FORMATS), "auto")
    conf = d.get("min_confidence", 0.1)
    if isinstance(conf, bool) or not isinstance(conf, int | float) or not 0 <= conf <= 1:
        raise KeypointFormatError(f"{path}: field 'min_confidence' must be in [0, 1], found {conf!r}")
    skeleton = d.get("skeleton")
    if skeleton is not None and not (isinstance(skeleton, dict) or (isinstance(skeleton, str) and skeleton)):
        raise KeypointFormatError(
            f"{path}: field 'skeleton' must be a skeleton name or table, found {skeleton!r}"
        )
    if isinstance(skeleton, dict):
        Skeleton.from_dict(
            skeleton, source=f"{path}: field 'skeleton'"
        )  # checked here, where the file is known
    return RecordingSpec(
        calibration=_path(path.parent, d["calibration"], "calibration", path),
        cameras=tuple(cams),
        calibration_units=units,
        clock=str(clock),
        keypoint_format=str(fmt),
        min_confidence=float(conf),
        skeleton=skeleton,
        ground_truth=None
        if "ground_truth" not in d
        else _path(path.parent, d["ground_truth"], "ground_truth", path),
    )


@dataclass(frozen=True)
class RecordingView:
    """Observations of a recording plus where each image came from.

    Args:
        observations: Solver inputs (undistorted pixels, confidences below the threshold missing).
        camera_names: Name of each camera index ``cam_id``, length V.
        frame: Video frame number of each image, shape ``(N,)``.
        stream_time_s: Each image's time on its own camera's clock, seconds, shape ``(N,)``, or None.
        image_index: Index of each view image in the recording's stored order (cameras in order, each
            camera's rows in frame order), shape ``(N,)``.
        fps: Frame rate per camera, Hz, shape ``(V,)`` (NaN where unknown).
        clock: One of :data:`CLOCKS`.
        source: Description for output files.
    """

    observations: Observations
    camera_names: tuple[str, ...]
    frame: np.ndarray
    stream_time_s: np.ndarray | None
    image_index: np.ndarray
    fps: np.ndarray
    clock: str
    source: str = ""


def _skeleton(names: tuple[str, ...], wanted: str | dict | None, kset: str, source: str = "") -> Skeleton:
    """The keypoints' topology of a recording.

    The keypoints' topology: a project's skeleton table or name, else the recognised keypoint set
    (a ``gttdata.skeletons`` name), else CMU-31 by its names, else a star rooted at joint 0.
    """
    from gttdata.skeletons import get_skeleton

    if isinstance(wanted, dict):
        sk = Skeleton.from_dict(wanted, source="project skeleton")
    else:
        name = wanted or kset or ("cmu31" if names == cmu31().joint_names else None)
        if name is None and len(candidate_sets(len(names))) > 1:
            both = " and ".join(candidate_sets(len(names)))
            raise KeypointFormatError(
                f"keypoints: {len(names)} joints fit {both}, which put different joints at the same "
                "index; name the skeleton (--skeleton, the project's 'skeleton' or Config.toml's pose_model)"
            )
        if name is None:
            return Skeleton(
                name=f"detector{len(names)}", joint_names=names, parents=(-1,) + (0,) * (len(names) - 1)
            )
        try:
            sk = get_skeleton(name)
        except KeyError as exc:
            from gttdata.skeletons_detectors import POSE2SIM_MODELS, pose2sim_model

            if str(name).strip().upper().replace("-", "_") not in POSE2SIM_MODELS:
                raise KeypointFormatError(f"{source}: skeleton: {exc.args[0]}") from None
            sk = get_skeleton(pose2sim_model(name))  # Pose2Sim's model names: COCO, Body_with_feet...
    if sk.n_joints != len(names):
        raise KeypointFormatError(
            f"{source}: skeleton {sk.name!r} has {sk.n_joints} joints but the keypoint sources have {len(names)}"
        )
    return sk


def _recording_skeleton(names: tuple[str, ...], wanted: str | dict | None, first: Keypoints2D) -> Skeleton:
    """:func:`_skeleton`, with a DeepLabCut file's limbs read from its project's ``config.yaml`` when found."""
    sk = _skeleton(names, wanted, first.keypoint_set, first.source)
    if wanted is None and first.fmt == "dlc" and sk.name.startswith("detector"):
        from gttdata.skeletons_detectors import dlc_project_edges, skeleton_from_edges

        found = dlc_project_edges(first.source)
        if found is not None:
            sk = skeleton_from_edges(f"dlc{len(names)}", names, found[1])
    return sk


def _last_number(name: str) -> int | None:
    m = re.search(r"(\d+)(?!.*\d)", name)
    return int(m.group(1)) if m else None


def _by_number(cam: CameraInput, by_name: dict) -> CameraInput:
    """``cam`` renamed to the one calibration camera with the same last number (``cam01`` -> ``cam_01``).

    A name the calibration has, or a number no or several calibration cameras share, is kept as it is.
    """
    n = _last_number(cam.name)
    if cam.name in by_name or n is None:
        return cam
    same = [k for k in by_name if _last_number(k) == n]
    if len(same) != 1:
        return cam
    log.info("camera %r matched to calibration camera %r by its number", cam.name, same[0])
    return dataclasses.replace(cam, name=same[0])


def _outside_image(kp: Keypoints2D, camera: Camera) -> Keypoints2D:
    """``kp`` with keypoints more than one image size outside ``camera``'s image made missing, with a warning.

    A detection lies in the image, give or take a lens's distortion; one beyond ``[-W, 2W] x [-H, 2H]``
    (-5000 px, 1e300 px) is a unit or column mistake, and one such point pulls a triangulation metres off.
    """
    w, h = camera.image_size
    x, y = kp.xy[..., 0], kp.xy[..., 1]
    with np.errstate(invalid="ignore"):
        far = (x < -w) | (x > 2 * w) | (y < -h) | (y > 2 * h)
    if not far.any():
        return kp
    r, j = (int(v[0]) for v in np.nonzero(far))
    log.warning(
        "%s: camera %r: %d keypoint(s) lie more than one image size outside its %dx%d image (first: frame %d "
        "joint %r at (%.4g, %.4g) px); treated as missing",
        kp.source, camera.name, int(far.sum()), w, h, int(kp.frame[r]), kp.joint_names[j], x[r, j], y[r, j],
    )  # fmt: skip
    return dataclasses.replace(
        kp, xy=np.where(far[..., None], np.nan, kp.xy), score=np.where(far, np.nan, kp.score)
    )


@dataclass(frozen=True)
class Recording:
    """A loaded recording.

    Args:
        rig: The recording's cameras, in the order of ``keypoints`` (metres, ``cam_from_world``).
        keypoints: 2-D detections per camera (raw, distorted pixels).
        stream_time_s: Per camera, each row's time on that camera's clock, seconds, shape ``(F_v,)``, or None.
        fps: Frame rate per camera, Hz, shape ``(V,)`` (NaN where unknown).
        clock: One of :data:`CLOCKS`.
        skeleton: Joint topology of the keypoints.
        calibration_units: Unit the calibration was read in.
        source: Calibration path, for output files.
    """

    rig: CameraRig
    keypoints: tuple[Keypoints2D, ...]
    stream_time_s: tuple[np.ndarray | None, ...]
    fps: np.ndarray
    clock: str
    skeleton: Skeleton
    calibration_units: str = "m"
    source: str = ""
    extra: dict = field(default_factory=dict, compare=False)

    @classmethod
    def load(cls, spec: RecordingSpec) -> Recording:
        """Read the calibration, every keypoint source and its timing, and check they agree.

        A camera whose source holds no detection at all (e.g. it never saw the subject) is left out with a
        warning; the others are reconstructed as usual.

        Raises:
            CalibrationError: A camera name that the calibration does not have.
            KeypointFormatError: A malformed source, joint names differing between cameras, or a
                timestamp file shorter than its keypoint source.
            NoDetectionsError: No camera has a single detection.
        """
        rig, units = load_calibration(spec.calibration, units=spec.calibration_units)
        by_name = {c.name: c for c in rig.cameras}
        if spec.clock not in CLOCKS:
            raise KeypointFormatError(f"clock must be one of {', '.join(CLOCKS)}, got {spec.clock!r}")
        names_seen = [c.name for c in spec.cameras]
        if len(set(names_seen)) != len(names_seen):
            raise KeypointFormatError(f"camera names must be unique, got {names_seen}")
        cams, kps, times, fps = [], [], [], []
        empty: list[str] = []
        joint_names = None
        used: set[str] = set()
        for c in spec.cameras:
            c = _by_number(c, by_name)
            if c.name in used:
                raise KeypointFormatError(f"{c.keypoints}: a second keypoint source for camera {c.name!r}")
            used.add(c.name)
            if c.name not in by_name:
                raise CalibrationError(
                    f"{c.keypoints}: camera {c.name!r} is not in calibration {spec.calibration} "
                    f"(its cameras: {', '.join(by_name)}); name the camera as NAME=PATH or in the project file"
                )
            try:
                kp = read_keypoints(c.keypoints, spec.keypoint_format)
            except NoDetectionsError as exc:  # a camera that never saw anyone adds nothing: leave it out
                empty.append(str(exc))
                log.warning("%s; camera %r left out", exc, c.name)
                continue
            kp = _outside_image(kp, by_name[c.name])
            if joint_names is None:
                joint_names, first = kp.joint_names, kp
            elif kp.joint_names != joint_names:
                raise KeypointFormatError(
                    f"{kp.source}: joint names {list(kp.joint_names)[:4]}... ({kp.n_joints}) differ from "
                    f"{first.source}'s ({len(joint_names)}); every camera needs the same keypoint set"
                )
            t = None
            if c.timestamps is not None:
                ts = read_timestamps_csv(c.timestamps)
                if kp.frame[-1] >= ts.shape[0]:
                    raise KeypointFormatError(
                        f"{c.timestamps}: has {ts.shape[0]} frame times but {kp.source} has frame "
                        f"{int(kp.frame[-1])} (frame counts do not match)"
                    )
                t = ts[kp.frame]
                rate = 1.0 / float(np.median(np.diff(ts))) if ts.shape[0] > 1 else np.nan
            elif c.fps is not None:
                t = kp.frame / float(c.fps)
                rate = float(c.fps)
            else:
                rate = np.nan
            cams.append(by_name[c.name])
            kps.append(kp)
            times.append(t)
            fps.append(rate)
        if joint_names is None:
            raise NoDetectionsError(
                f"no camera has a detection: {empty[0]}"
                + (f" (and {len(empty) - 1} more)" if len(empty) > 1 else "")
            )
        sk = _recording_skeleton(joint_names, spec.skeleton, kps[0])
        return cls(
            rig=CameraRig(tuple(cams)),
            keypoints=tuple(kps),
            stream_time_s=tuple(times),
            fps=np.asarray(fps, dtype=np.float64),
            clock=spec.clock,
            skeleton=sk,
            calibration_units=units,
            source=str(spec.calibration),
            extra={"min_confidence": spec.min_confidence},
        )

    @property
    def camera_names(self) -> tuple[str, ...]:
        """Camera names in ``cam_id`` order."""
        return tuple(c.name for c in self.rig.cameras)

    def best_sequencing(self) -> str:
        """``full`` for a shared clock with timing on every camera, ``partial`` otherwise."""
        timed = all(t is not None for t in self.stream_time_s)
        return "full" if self.clock == "shared" and timed else "partial"

    def view(
        self,
        sequencing: str | None = None,
        *,
        min_confidence: float | None = None,
        undistort: bool = True,
        weights: bool = True,
        seed: int = 0,
    ) -> RecordingView:
        """Solver inputs of the recording.

        Pixels are undistorted with each camera's distortion coefficients; detections scoring below
        ``min_confidence`` are missing and the others keep their score as ``confidence``. Rows with no
        joint left stay (all joints missing), as in a simulated capture.

        Args:
            sequencing: ``none``, ``partial`` or ``full`` (None: :meth:`best_sequencing`).
            min_confidence: Missing threshold (None: the project's, default 0.1).
            undistort: Undo lens distortion (turn off only to measure what it costs).
            weights: Pass the detector scores on as per-observation weights (``confidence``); False
                keeps only the missing threshold.
            seed: Seed of the image shuffle under ``none``.
        """
        seq = sequencing or self.best_sequencing()
        if seq not in SEQUENCING:
            raise ValueError(f"sequencing must be one of {SEQUENCING}, got {seq!r}")
        if seq == "full" and self.best_sequencing() != "full":
            raise KeypointFormatError(
                "sequencing 'full' needs every camera's timestamps on one shared clock (clock = \"shared\"); "
                "cameras with their own clocks give 'partial'"
            )
        thr = float(self.extra.get("min_confidence", 0.1) if min_confidence is None else min_confidence)
        parts: tuple[list[np.ndarray], ...] = ([], [], [], [], [])  # px, conf, cam, frame, times
        for v, (kp, cam_v) in enumerate(zip(self.keypoints, self.rig.cameras, strict=True)):
            xy = undistort_points(kp.xy, cam_v) if undistort else kp.xy
            ok = np.isfinite(kp.score) & (kp.score >= thr) & np.all(np.isfinite(xy), axis=-1)
            if not ok.any():
                log.warning("camera %r: no usable detection (%s)", cam_v.name, _why_blind(kp, cam_v, thr))
            t = self.stream_time_s[v]
            for part, value in zip(parts, (
                np.where(ok[..., None], xy, np.nan), np.where(ok, kp.score, 0.0), np.full(kp.n_frames, v),
                kp.frame, np.full(kp.n_frames, np.nan) if t is None else t,
            ), strict=True):  # fmt: skip
                part.append(value)
        px, conf, cam, frame, times = (np.concatenate(part) for part in parts)
        vis = conf > 0
        keep = np.arange(cam.shape[0])  # images without any detection stay: they still have a time
        if seq == "full":
            perm = keep[np.argsort(times[keep], kind="stable")]
        elif seq == "partial":
            perm = keep[np.lexsort((frame[keep], cam[keep]))]
        else:
            perm = keep[np.random.default_rng(seed).permutation(keep.size)]
        timed = all(t is not None for t in self.stream_time_s)
        K = self.rig.K[cam[perm]]
        obs = Observations(
            sequencing=seq,
            skeleton=self.skeleton,
            cam_id=cam[perm].astype(np.int32),
            K=K,
            cam_from_world=self.rig.cam_from_world[cam[perm]],
            keypoints_px=px[perm],
            visible=vis[perm],
            image_size=np.array([c.image_size for c in self.rig.cameras], dtype=np.int32),
            stream_index=None if seq == "none" else frame[perm].astype(np.int64),
            timestamp_s=times[perm] if seq == "full" else None,
            stream_time_s=times[perm] if (timed and seq != "none") else None,
            confidence=conf[perm] if weights else None,
        )
        return RecordingView(
            observations=obs,
            camera_names=self.camera_names,
            frame=frame[perm],
            stream_time_s=times[perm] if timed else None,
            image_index=perm.astype(np.int64),
            fps=self.fps,
            clock=self.clock,
            source=self.source,
        )


def _why_blind(kp, camera, threshold: float) -> str:
    """Why none of a camera's detections is usable: NaN distortion, NaN scores, or all below the threshold."""
    if not np.all(np.isfinite(camera.dist)):
        return f"its distortion coefficients {list(camera.dist)} are not finite"
    score = np.asarray(kp.score, dtype=np.float64)
    if not np.isfinite(score).any():
        return "every detection score is NaN"
    if not (score[np.isfinite(score)] >= threshold).any():
        return f"every detection scores below the confidence threshold {threshold:g} (best {np.nanmax(score):.3g})"
    return "no detection has finite pixel coordinates"


def ground_truth_for(view: RecordingView, path: str | Path) -> np.ndarray:
    """Ground-truth joints of each view image from an exported ``ground_truth.npz``, metres, ``(N, J, 3)``.

    Images are matched by camera name and frame number. For scoring only: never pass it to a solver.

    Raises:
        KeypointFormatError: A camera or frame that the file does not hold.
    """
    path = Path(path)
    with np.load(path, allow_pickle=False) as z:  # a file from anyone: arrays only, never pickles
        gt = {
            k[: -len("_frame")]: (z[k], z[k[: -len("_frame")] + "_points3d"])
            for k in z.files
            if k.endswith("_frame")
        }
    obs = view.observations
    out = np.full((obs.n_images, obs.n_joints, 3), np.nan)
    for v, name in enumerate(view.camera_names):
        if name not in gt:
            raise KeypointFormatError(f"{path}: no ground truth for camera {name!r}")
        frames, X = gt[name]
        rows = np.flatnonzero(obs.cam_id == v)
        pos = np.searchsorted(frames, view.frame[rows])
        if np.any(pos >= frames.shape[0]) or np.any(
            frames[np.minimum(pos, frames.shape[0] - 1)] != view.frame[rows]
        ):
            raise KeypointFormatError(f"{path}: camera {name!r} lacks ground truth for some frames")
        out[rows] = X[pos]
    return out
