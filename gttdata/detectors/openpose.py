"""OpenPose JSON: one folder per camera, one ``*_keypoints.json`` file per video frame (Pose2Sim layout).

Each file holds ``{"people": [{"pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...]}, ...]}``. A joint
OpenPose did not find is written as ``0, 0, 0``. The frame number is the last group of digits in the
file name (``cam1_000000000042_keypoints.json`` is frame 42); when no file name has digits the files
are numbered in name order. A stray file (another name pattern) or two files of one frame number are
skipped with a warning naming them, never renumbered. A person written as ``{}`` or with an empty list
(Pose2Sim's ``pose-associated`` output for a frame where the tracked person was not found) is nobody.
With several people in a frame the one with the highest summed confidence is kept (one
subject per capture).
"""

from __future__ import annotations

import json
import logging
import os
import re
from collections import Counter
from pathlib import Path

import numpy as np

from gttdata.detectors import Keypoints2D, keypoint_set_for, read_json
from gttdata.errors import KeypointFormatError, NoDetectionsError

__all__ = [
    "SUMMARY",
    "frame_files",
    "frame_number",
    "read_openpose",
    "write_openpose",
]

log = logging.getLogger(__name__)

SUMMARY = "OpenPose JSON, a folder per camera, one *_keypoints.json per frame (Body-25, COCO-17, Halpe-26)"

_DIGITS = re.compile(r"(\d+)(?!.*\d)")


def frame_number(name: str) -> int | None:
    """Frame number in an OpenPose file name: its last group of digits, or None."""
    m = _DIGITS.search(Path(name).name)
    return int(m.group(1)) if m else None


def _template(name: str) -> str:
    """A file name with its frame number (last group of digits) replaced by ``#``: the camera's name pattern."""
    m = _DIGITS.search(name)
    return name if m is None else f"{name[: m.start()]}#{name[m.end() :]}"


def _names(paths: list[Path]) -> str:
    shown = ", ".join(p.name for p in paths[:4])
    return shown + (f" and {len(paths) - 4} more" if len(paths) > 4 else "")


def frame_files(folder: Path, files: list[Path]) -> list[tuple[int, Path]]:
    """The camera's frame files in frame order, ``[(frame number, path), ...]``.

    The camera's files share one name pattern (the name with its last group of digits replaced, e.g.
    ``cam1_#_keypoints.json``): the pattern most files have. A file with another pattern (a stray
    ``del_000001_0.json`` left beside the frames) and every file of a frame number that two files claim
    (``cam1_01_keypoints.json`` and ``cam1_001_keypoints.json``) are skipped with a warning naming them,
    never renumbered. When no file name holds digits the files are numbered in name order.

    Raises:
        KeypointFormatError: Two name patterns are equally common (which files are the frames is unknown).
    """
    if all(frame_number(f.name) is None for f in files):
        return list(enumerate(files))
    counts = Counter(_template(f.name) for f in files)
    (main, n_main), *rest = counts.most_common()
    if rest and rest[0][1] == n_main:
        raise KeypointFormatError(
            f"{folder}: the JSON files follow {len(counts)} name patterns, {n_main} files each "
            f"({main!r}, {rest[0][0]!r}); cannot tell the frame files from stray ones: move the others out"
        )
    stray = [f for f in files if _template(f.name) != main]
    if stray:
        log.warning(
            "%s: %d JSON file(s) do not follow the frame files' name pattern %r and are skipped: %s",
            folder, len(stray), main, _names(stray),
        )  # fmt: skip
    by_frame: dict[int, list[Path]] = {}
    for f in files:
        if _template(f.name) == main:
            by_frame.setdefault(int(frame_number(f.name) or 0), []).append(f)
    dups = sorted(f for group in by_frame.values() if len(group) > 1 for f in group)
    if dups:
        log.warning(
            "%s: %d JSON files share a frame number with another file and are skipped (which one is the "
            "frame is unknown): %s",
            folder, len(dups), _names(dups),
        )  # fmt: skip
    out = sorted((n, group[0]) for n, group in by_frame.items() if len(group) == 1)
    if out and out[-1][0] >= 2**62:
        raise KeypointFormatError(f"{out[-1][1]}: frame number {out[-1][0]} in the file name is too large")
    return out


def _people(path: Path, doc: object) -> list[np.ndarray]:
    """Every person's flat keypoint array in a frame file (``{}`` persons are nobody)."""
    if not isinstance(doc, dict) or not isinstance(doc.get("people"), list):
        raise KeypointFormatError(f"{path}: field 'people' must be a list, found {type(doc).__name__}")
    out = []
    for i, person in enumerate(doc["people"]):
        flat = person.get("pose_keypoints_2d") if isinstance(person, dict) else None
        if isinstance(person, dict) and not flat:  # Pose2Sim's pose-associated files: {} for nobody
            continue
        ok = isinstance(flat, list) and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in flat
        )
        arr = np.asarray(flat, dtype=np.float64) if ok else np.zeros(1)
        if arr.ndim != 1 or arr.size == 0 or arr.size % 3:
            found = f"{arr.size} values" if ok else repr(flat)[:60]
            raise KeypointFormatError(
                f"{path}: field 'people[{i}].pose_keypoints_2d' must be a flat list of 3*J numbers, found {found}"
            )
        out.append(arr)
    return out


def _best(people: list[np.ndarray]) -> np.ndarray | None:
    """The person kept for a frame: the highest summed confidence, or None when the frame has nobody."""
    best, best_score = None, -np.inf
    for arr in people:
        score = float(np.nansum(arr[2::3]))
        if best is None or score > best_score:
            best, best_score = arr, score
    return best


def read_openpose(folder: Path) -> Keypoints2D:
    """Read a folder of OpenPose JSON files (one camera).

    Stray files and files of a duplicated frame number are skipped with a warning (:func:`frame_files`).

    Raises:
        KeypointFormatError: No JSON files, unreadable JSON, or joint counts that change between files.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise KeypointFormatError(f"{folder}: an OpenPose source must be a folder of *.json files")
    files = sorted(folder.glob("*.json"))
    if not files:
        raise KeypointFormatError(f"{folder}: no OpenPose *.json files in the folder")
    frames = frame_files(folder, files)
    if not frames:
        raise KeypointFormatError(f"{folder}: no frame file left once stray and duplicate files are skipped")
    rows: list[np.ndarray | None] = []
    everyone: list[tuple[int, np.ndarray]] = []  # every person of every frame, for a crowded camera
    n_joints = None
    for n, path in frames:
        people = _people(path, read_json(path))
        arr = _best(people)
        everyone += [(n, a) for a in people]
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
        raise NoDetectionsError(f"{folder}: no person detected in any of the {len(frames)} files")
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
        frame=np.asarray([n for n, _ in frames], dtype=np.int64),
        joint_names=names,
        keypoint_set=kset,
        source=str(folder),
        fmt="openpose",
        crowd=_crowd(folder, everyone, len(frames)),
    )


def _crowd(
    folder: Path, everyone: list[tuple[int, np.ndarray]], n_frames: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Every person of every frame, or None when no frame held two people.

    Returns ``(frame (M,), xy (M, J, 2), score (M, J))``, NaN where a joint was not found.

    Raises:
        KeypointFormatError: People with different joint counts.
    """
    if len(everyone) <= len({n for n, _ in everyone}):
        return None
    sizes = {a.size for _, a in everyone}
    if len(sizes) != 1:
        raise KeypointFormatError(
            f"{folder}: people with different joint counts ({sorted(s // 3 for s in sizes)})"
        )
    a = np.stack([r for _, r in everyone]).reshape(len(everyone), sizes.pop() // 3, 3)
    found = a[..., 2] > 0  # OpenPose writes 0, 0, 0 for a joint it did not find
    xy = np.where(found[..., None], a[..., :2], np.nan)
    return np.asarray([n for n, _ in everyone], dtype=np.int64), xy, np.where(found, a[..., 2], np.nan)


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
