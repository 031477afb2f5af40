"""2-D detector outputs (OpenPose, DeepLabCut, SLEAP, COCO/MMPose): one reader per format, in a registry.

Every reader returns :class:`Keypoints2D`, the detections of ONE camera stream: pixel coordinates, a
confidence per joint, the video frame number of each row and the joint names, nothing else. Which
skeleton the names belong to, the calibration and the timing are attached later
(:mod:`gttdata.recording`).

``read_keypoints(path, fmt="auto")`` picks the format from the path: a folder of ``*.json`` files is
OpenPose, ``.h5``/``.csv`` is DeepLabCut, ``.slp`` is SLEAP, a single ``.json`` file is COCO results or
MMPose predictions. ``write_keypoints`` writes the OpenPose and DeepLabCut layouts (used by
``gttdata export`` to turn a simulated capture into detector files).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gttdata.errors import KeypointFormatError

__all__ = [
    "FORMATS",
    "KEYPOINT_SETS",
    "Keypoints2D",
    "KeypointFormat",
    "detect_format",
    "candidate_sets",
    "keypoint_set_for",
    "read_json",
    "read_keypoints",
    "write_keypoints",
]

#: The detector keypoint sets a joint count identifies, as ``gttdata.skeletons`` names (OpenPose and
#: COCO files carry no joint names): their joint names and order are those skeletons'. BODY_25 and
#: BODY_25B share a count (25) and are never guessed: see :func:`candidate_sets`.
_DETECTOR_SETS: tuple[str, ...] = (
    "coco17", "coco18", "hand21", "body25", "body25b", "halpe26", "blazepose33", "halpe68", "coco133",
    "body135", "halpe136",
)  # fmt: skip


def _keypoint_sets() -> dict[str, tuple[str, ...]]:
    from gttdata.skeletons import get_skeleton

    return {k: get_skeleton(k).joint_names for k in _DETECTOR_SETS}


#: Joint names of each detector keypoint set in the detector's output order (from ``gttdata.skeletons``).
KEYPOINT_SETS: dict[str, tuple[str, ...]] = _keypoint_sets()

_COUNTS = [len(v) for v in KEYPOINT_SETS.values()]
_SET_BY_COUNT = {len(v): k for k, v in KEYPOINT_SETS.items() if _COUNTS.count(len(v)) == 1}


def candidate_sets(n_joints: int) -> tuple[str, ...]:
    """Every detector keypoint set with ``n_joints`` joints (two for 25: ``body25`` and ``body25b``)."""
    return tuple(k for k, v in KEYPOINT_SETS.items() if len(v) == int(n_joints))


def keypoint_set_for(n_joints: int) -> tuple[str, tuple[str, ...]]:
    """Keypoint set recognised from a joint count: ``(set name, joint names)``.

    A count that names one set gives it (17 COCO-17, 18 OpenPose COCO, 26 Halpe-26, 33 BlazePose, 133
    COCO-133...; the skeletons of ``gttdata.skeletons``). A count two sets share (25: BODY_25 and
    BODY_25B) or no set has gives ``("", ("kp0", ...))``: the skeleton must then be named.
    """
    name = _SET_BY_COUNT.get(int(n_joints), "")
    if name:
        return name, KEYPOINT_SETS[name]
    return "", tuple(f"kp{i}" for i in range(int(n_joints)))


def read_json(path: Path) -> object:
    """Parse a detector's JSON file; invalid, binary or absurdly nested text is one line naming the file.

    Raises:
        KeypointFormatError: The file is not valid UTF-8 JSON.
    """
    try:
        return json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise KeypointFormatError(f"{path}: not valid JSON: {exc}") from exc
    except RecursionError:
        raise KeypointFormatError(f"{path}: not valid JSON: nested too deeply") from None


@dataclass(frozen=True)
class Keypoints2D:
    """The 2-D detections of one camera stream.

    Args:
        xy: Joint positions, pixels (origin at the top-left corner), shape ``(F, J, 2)`` float64; NaN
            where the detector found nothing. Infinite values are refused (:class:`KeypointFormatError`).
        score: Detector confidence in ``[0, 1]``, shape ``(F, J)`` float64; NaN where nothing was found.
        frame: Video frame number of each row, shape ``(F,)`` int64, ``>= 0`` and strictly increasing
            (gaps are frames without a file or row).
        joint_names: Names of the J joints, in column order.
        keypoint_set: Name of the detector keypoint set (a key of :data:`KEYPOINT_SETS`) or ``""``.
        source: File or folder read, for messages.
        fmt: Format name (a key of :data:`FORMATS`).
        crowd: Where a frame held several people (rows keep the most confident): every person of every
            frame, ``(frame (M,) int64, xy (M, J, 2), score (M, J))`` with NaN where not found; None otherwise.
    """

    xy: np.ndarray
    score: np.ndarray
    frame: np.ndarray
    joint_names: tuple[str, ...]
    keypoint_set: str = ""
    source: str = ""
    fmt: str = ""
    crowd: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        xy = np.asarray(self.xy, dtype=np.float64)
        score = np.asarray(self.score, dtype=np.float64)
        frame = np.asarray(self.frame, dtype=np.int64)
        f, j = score.shape if score.ndim == 2 else (-1, -1)
        if xy.shape != (f, j, 2) or frame.shape != (f,) or len(self.joint_names) != j:
            raise KeypointFormatError(
                f"{self.source}: inconsistent keypoints: xy {xy.shape}, score {score.shape}, frame "
                f"{frame.shape}, {len(self.joint_names)} joint names"
            )
        inf = np.isinf(xy).any(axis=-1) | np.isinf(score)
        if inf.any():
            r, j = (int(v[0]) for v in np.nonzero(inf))
            raise KeypointFormatError(
                f"{self.source}: frame {frame[r]} joint {self.joint_names[j]!r}: expected finite pixel "
                f"coordinates and score (NaN marks a missing joint), found {xy[r, j].tolist()} "
                f"score {score[r, j]}"
            )
        if f > 0 and frame.min() < 0:
            raise KeypointFormatError(f"{self.source}: frame numbers must be >= 0, found {int(frame.min())}")
        if f > 1 and np.any(np.diff(frame) <= 0):
            k = int(np.flatnonzero(np.diff(frame) <= 0)[0])
            raise KeypointFormatError(
                f"{self.source}: frame numbers must increase, found {frame[k]} then {frame[k + 1]}"
            )
        missing = ~np.all(np.isfinite(xy), axis=-1) | ~np.isfinite(score)
        object.__setattr__(self, "xy", np.where(missing[..., None], np.nan, xy))
        object.__setattr__(self, "score", np.where(missing, np.nan, score))
        object.__setattr__(self, "frame", frame)
        object.__setattr__(self, "joint_names", tuple(str(n) for n in self.joint_names))

    @property
    def n_frames(self) -> int:
        """Number of rows F."""
        return int(self.frame.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return len(self.joint_names)


@dataclass(frozen=True)
class KeypointFormat:
    """A registered detector format.

    Args:
        name: Registry name.
        read: ``read(path) -> Keypoints2D``.
        write: ``write(kp, path) -> Path`` or None when only reading is supported.
        summary: One line for listings.
    """

    name: str
    read: Callable[[Path], Keypoints2D]
    write: Callable[[Keypoints2D, Path], Path] | None
    summary: str


def _registry() -> dict[str, KeypointFormat]:
    from gttdata.detectors import coco, dlc, openpose, sleap

    return {
        "openpose": KeypointFormat(
            "openpose", openpose.read_openpose, openpose.write_openpose, openpose.SUMMARY
        ),
        "dlc": KeypointFormat("dlc", dlc.read_dlc, dlc.write_dlc, dlc.SUMMARY),
        "sleap": KeypointFormat("sleap", sleap.read_sleap, None, sleap.SUMMARY),
        "coco": KeypointFormat("coco", coco.read_coco, coco.write_coco, coco.SUMMARY),
    }


#: Format names (``"auto"`` detects from the path).
FORMATS: tuple[str, ...] = ("openpose", "dlc", "sleap", "coco")


def detect_format(path: str | Path) -> str:
    """Format of a keypoint source from its path.

    A folder is OpenPose (one JSON per frame); ``.h5``/``.csv`` DeepLabCut; ``.slp`` SLEAP; ``.json``
    COCO results or MMPose predictions.

    Raises:
        KeypointFormatError: When the path names no known layout.
    """
    path = Path(path)
    if path.is_dir():
        return "openpose"
    suffix = path.suffix.lower()
    by_suffix = {".h5": "dlc", ".hdf5": "dlc", ".csv": "dlc", ".slp": "sleap", ".json": "coco"}
    if suffix in by_suffix:
        return by_suffix[suffix]
    raise KeypointFormatError(
        f"{path}: cannot tell the keypoint format from suffix {suffix!r}; expected a folder of OpenPose "
        "JSON files, .h5/.csv (DeepLabCut), .slp (SLEAP) or .json (COCO/MMPose)"
    )


def read_keypoints(path: str | Path, fmt: str = "auto") -> Keypoints2D:
    """Read one camera's 2-D detections.

    Args:
        path: A folder (OpenPose) or a file.
        fmt: ``"auto"`` or a key of :data:`FORMATS`.

    Raises:
        FileNotFoundError: When the path does not exist.
        KeypointFormatError: For a malformed file, with the file and field.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory (keypoint source)", str(path))
    fmt = detect_format(path) if fmt == "auto" else fmt
    reg = _registry()
    if fmt not in reg:
        raise ValueError(f"unknown keypoint format {fmt!r}; expected auto or one of {', '.join(FORMATS)}")
    return reg[fmt].read(path)


def write_keypoints(kp: Keypoints2D, path: str | Path, fmt: str) -> Path:
    """Write one camera's detections in a detector format.

    Write one camera's detections in ``fmt`` (``openpose``: a folder; ``dlc``: ``.h5`` or ``.csv``;
    ``coco``: one ``.json`` results file).
    """
    reg = _registry()
    write = reg[fmt].write if fmt in reg else None
    if write is None:
        writable = ", ".join(k for k, v in reg.items() if v.write is not None)
        raise ValueError(f"cannot write keypoint format {fmt!r}; writable: {writable}")
    return write(kp, Path(path))
