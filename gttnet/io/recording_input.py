"""Recording specs from command-line options, stored with results so ``gttnet render`` can reload them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gttdata.errors import KeypointFormatError
from gttdata.recording import CameraInput, RecordingSpec, RecordingView

__all__ = ["spec_from_options", "spec_to_json", "spec_from_json", "view_of_loaded"]


def _camera_name(path: Path) -> str:
    name = path.name if path.is_dir() else path.stem
    for tail in ("_json", "_keypoints"):
        if name.endswith(tail) and len(name) > len(tail):
            name = name[: -len(tail)]
    return name


def spec_from_options(
    calibration: str | Path,
    keypoints: list[str],
    *,
    fps: tuple[float, ...] = (),
    timestamps: tuple[str, ...] = (),
    clock: str = "per-camera",
    calibration_units: str | None = None,
    min_confidence: float = 0.1,
    keypoint_format: str = "auto",
) -> RecordingSpec:
    """A :class:`~gttdata.recording.RecordingSpec` from ``--calibration``/``--keypoints``/``--fps``/``--timestamps``.

    Each keypoint source is ``PATH`` (the camera is named after the folder, or the file's stem, less a
    ``_json`` or ``_keypoints`` tail) or ``NAME=PATH``. ``fps`` is one rate for every camera or one per
    camera; ``timestamps`` one CSV per camera, in the order of the keypoint sources.

    Raises:
        KeypointFormatError: Counts of ``--fps`` or ``--timestamps`` that match neither 1 nor the cameras.
    """
    if not keypoints:
        raise KeypointFormatError("--keypoints: give one keypoint source (folder or file) per camera")
    n = len(keypoints)
    if len(fps) not in (0, 1, n):
        raise KeypointFormatError(
            f"--fps: give one rate for all cameras or one per camera ({n}), got {len(fps)}"
        )
    if len(timestamps) not in (0, n):
        raise KeypointFormatError(f"--timestamps: give one CSV per camera ({n}), got {len(timestamps)}")
    cams = []
    for i, src in enumerate(keypoints):
        name, _, rest = src.partition("=")
        path = Path(rest if rest else src)
        cams.append(
            CameraInput(
                name=name if rest else _camera_name(path),
                keypoints=path,
                fps=(fps[0] if len(fps) == 1 else fps[i]) if fps else None,
                timestamps=Path(timestamps[i]) if timestamps else None,
            )
        )
    return RecordingSpec(
        calibration=Path(calibration),
        cameras=tuple(cams),
        calibration_units=calibration_units,
        clock=clock,
        keypoint_format=keypoint_format,
        min_confidence=min_confidence,
    )


def spec_to_json(spec: RecordingSpec) -> str:
    """The spec as JSON (absolute paths), stored in a result's attributes."""
    d = {
        "calibration": str(Path(spec.calibration).resolve()),
        "calibration_units": spec.calibration_units,
        "clock": spec.clock,
        "keypoint_format": spec.keypoint_format,
        "min_confidence": spec.min_confidence,
        "skeleton": spec.skeleton,
        "cameras": [
            {
                "name": c.name,
                "keypoints": str(Path(c.keypoints).resolve()),
                "fps": c.fps,
                "timestamps": None if c.timestamps is None else str(Path(c.timestamps).resolve()),
            }
            for c in spec.cameras
        ],
    }
    return json.dumps(d)


def spec_from_json(text: str) -> RecordingSpec:
    """Inverse of :func:`spec_to_json`."""
    d = json.loads(text)
    return RecordingSpec(
        calibration=Path(d["calibration"]),
        cameras=tuple(
            CameraInput(
                name=c["name"],
                keypoints=Path(c["keypoints"]),
                fps=c["fps"],
                timestamps=None if c["timestamps"] is None else Path(c["timestamps"]),
            )
            for c in d["cameras"]
        ),
        calibration_units=d["calibration_units"],
        clock=d["clock"],
        keypoint_format=d["keypoint_format"],
        min_confidence=d["min_confidence"],
        skeleton=d["skeleton"],
    )


def view_of_loaded(loaded) -> RecordingView:
    """A recording view of a shard / .mat / .json input.

    A :class:`~gttdata.recording.RecordingView` of a shard / .mat / .json input (cameras ``cam_<v>``,
    frame = stream index, rates unknown), so motion files can be written for any input.
    """
    obs = loaded.observations
    v = int(np.asarray(obs.image_size).shape[0])
    frame = obs.stream_index if obs.stream_index is not None else np.full(obs.n_images, -1)
    return RecordingView(
        observations=obs,
        camera_names=tuple(f"cam_{i}" for i in range(v)),
        frame=np.asarray(frame, dtype=np.int64),
        stream_time_s=None,
        image_index=np.asarray(loaded.image_index, dtype=np.int64),
        fps=np.full(v, np.nan),
        clock="per-camera",
        source=loaded.source,
    )
