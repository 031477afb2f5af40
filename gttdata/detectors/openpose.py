"""OpenPose JSON: one folder per camera, one ``*_keypoints.json`` file per video frame (Pose2Sim layout).

Each file holds ``{"people": [{"pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...]}, ...]}``. A joint
OpenPose did not find is written as ``0, 0, 0``. The frame number is the last group of digits in the
file name (``cam1_000000000042_keypoints.json`` is frame 42); files without digits are numbered in
name order. A person written as ``{}`` or with an empty list (Pose2Sim's ``pose-associated`` output
for a frame where the tracked person was not found) is nobody. With several people in a frame the one with the highest summed confidence is kept (one
subject per capture).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np

from gttdata.detectors import Keypoints2D, keypoint_set_for
from gttdata.errors import KeypointFormatError, NoDetectionsError

__all__ = ["SUMMARY", "read_openpose", "write_openpose", "frame_number"]

SUMMARY = "OpenPose JSON, a folder per camera, one *_keypoints.json per frame (Body-25, COCO-17, Halpe-26)"

_DIGITS = re.compile(r"(\d+)(?!.*\d)")


def frame_number(name: str) -> int | None:
    """Frame number in an OpenPose file name: its last group of digits, or None."""
    m = _DIGITS.search(Path(name).name)
    return int(m.group(1)) if m else None


def _person(path: Path, doc: object) -> np.ndarray | None:
    """The kept person's flat keypoint array, or None when the frame has nobody."""
    if not isinstance(doc, dict) or not isinstance(doc.get("people"), list):
        raise KeypointFormatError(f"{path}: field 'people' must be a list, found {type(doc).__name__}")
    best, best_score = None, -np.inf
    for i, person in enumerate(doc["people"]):
        flat = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
        if isinstance(person, dict) and not flat:  # Pose2Sim's pose-associated files: {} for nobody
            continue
        try:
            arr = np.asarray(flat, dtype=np.float64)
        except (TypeError, ValueError):
            arr = np.zeros(1)
        if arr.ndim != 1 or arr.size == 0 or arr.size % 3:
            raise KeypointFormatError(
                f"{path}: field 'people[{i}].pose_keypoints_2d' must be a flat list of 3*J numbers, "
                f"found {np.shape(flat) if flat is not None else 'nothing'}"
            )
        score = float(np.nansum(arr[2::3]))
        if score > best_score:
            best, best_score = arr, score
    return best


def read_openpose(folder: Path) -> Keypoints2D:
    """Read a folder of OpenPose JSON files (one camera).

    Raises:
        KeypointFormatError: No JSON files, unreadable JSON, or joint counts that change between files.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise KeypointFormatError(f"{folder}: an OpenPose source must be a folder of *.json files")
    files = sorted(folder.glob("*.json"))
    if not files:
        raise KeypointFormatError(f"{folder}: no OpenPose *.json files in the folder")
    parsed = [frame_number(f.name) for f in files]
    numbers = [n for n in parsed if n is not None]
    if len(numbers) != len(parsed) or len(set(numbers)) != len(numbers):
        numbers = list(range(len(files)))
    order = np.argsort(numbers, kind="stable")
    rows: list[np.ndarray | None] = []
    n_joints = None
    for k in order:
        path = files[k]
        try:
            doc = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise KeypointFormatError(f"{path}: not valid JSON: {exc}") from exc
        arr = _person(path, doc)
        if arr is not None:
            if n_joints is None:
                n_joints = arr.size // 3
            elif arr.size // 3 != n_joints:
                raise KeypointFormatError(
                    f"{path}: field 'pose_keypoints_2d' has {arr.size // 3} joints, expected {n_joints} "
                    f"as in the folder's earlier files"
                )
        rows.append(arr)
    if n_joints is None:
        raise NoDetectionsError(f"{folder}: no person detected in any of the {len(files)} files")
    xy = np.full((len(rows), n_joints, 2), np.nan)
    score = np.full((len(rows), n_joints), np.nan)
    for i, arr in enumerate(rows):
        if arr is None:
            continue
        a = arr.reshape(n_joints, 3)
        found = a[:, 2] > 0  # OpenPose writes 0, 0, 0 for a joint it did not find
        xy[i] = np.where(found[:, None], a[:, :2], np.nan)
        score[i] = np.where(found, a[:, 2], np.nan)
    kset, names = keypoint_set_for(n_joints)
    return Keypoints2D(
        xy=xy,
        score=score,
        frame=np.asarray(numbers, dtype=np.int64)[order],
        joint_names=names,
        keypoint_set=kset,
        source=str(folder),
        fmt="openpose",
    )


def write_openpose(kp: Keypoints2D, folder: Path, *, prefix: str | None = None) -> Path:
    """Write one JSON file per row, ``<prefix>_<frame:012d>_keypoints.json``, into ``folder``.

    Missing joints are written as ``0, 0, 0``; a row with no joint found has an empty ``people`` list.
    Coordinates and scores are written at full float64 precision.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    prefix = prefix or folder.name
    for f, xy, sc in zip(kp.frame.tolist(), kp.xy, kp.score, strict=True):
        found = np.isfinite(sc)
        flat = np.stack(
            [np.where(found, xy[:, 0], 0.0), np.where(found, xy[:, 1], 0.0), np.where(found, sc, 0.0)], 1
        )
        people = [{"person_id": [-1], "pose_keypoints_2d": flat.ravel().tolist()}] if found.any() else []
        path = folder / f"{prefix}_{f:012d}_keypoints.json"
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps({"version": 1.3, "people": people}))
        os.replace(tmp, path)
    return folder
