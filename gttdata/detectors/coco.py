"""COCO keypoint results and MMPose predictions: one ``.json`` file per camera.

Two layouts are read:

* **COCO results** (what COCO-style evaluators and many detectors write): a list of
  ``{"image_id": int, "keypoints": [x0, y0, s0, ...], "score": float}``, or a COCO dataset dict whose
  ``"annotations"`` hold such entries. ``image_id`` is the frame number; ``s`` is the per-joint score
  (a visibility flag 0/1/2 in ground-truth files, read as 0, 0.5, 1). Joints with ``s = 0`` are missing.
* **MMPose predictions** (``--save-predictions``): ``{"meta_info": {...}, "instance_info": [{"frame_id":
  int, "instances": [{"keypoints": [[x, y], ...], "keypoint_scores": [...]}]}]}``; joint names come
  from ``meta_info.keypoint_id2name`` when present.

With several detections in a frame the highest-scoring one is kept (one subject per capture).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from gttdata.detectors import Keypoints2D, keypoint_set_for, read_json
from gttdata.errors import KeypointFormatError, NoDetectionsError

__all__ = ["SUMMARY", "read_coco", "write_coco"]

SUMMARY = "COCO keypoint results or MMPose predictions, one .json per camera"


def _frame(path: Path, value: object, where: str) -> int:
    """A frame number (``image_id``, ``frame_id``): an integer in ``[0, 2^62)``."""
    if isinstance(value, int | float) and not isinstance(value, bool):
        if float(value).is_integer() and 0 <= value < 2**62:
            return int(value)
    raise KeypointFormatError(f"{path}: {where}: expected a frame number (an integer >= 0), found {value!r}")


def _numbers(path: Path, value: object, where: str) -> np.ndarray:
    """A numeric array (float64); strings, nulls, booleans and ragged lists are one line naming the field."""
    if isinstance(value, bool | str) or value is None:
        raise KeypointFormatError(f"{path}: {where}: expected numbers, found {value!r}")
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise KeypointFormatError(f"{path}: {where}: expected a rectangular list of numbers") from None
    if a.dtype != np.float64 or any(
        isinstance(v, bool | str) for v in np.asarray(value, dtype=object).ravel()
    ):
        raise KeypointFormatError(f"{path}: {where}: expected numbers, found a string or boolean")
    return a


def _coco_rows(path: Path, entries: list) -> dict[int, tuple[np.ndarray, np.ndarray, float]]:
    best: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
    for i, e in enumerate(entries):
        if not isinstance(e, dict) or "keypoints" not in e or "image_id" not in e:
            raise KeypointFormatError(f"{path}: entry {i} needs fields 'image_id' and 'keypoints'")
        a = _numbers(path, e["keypoints"], f"entry {i} field 'keypoints'")
        frame = _frame(path, e["image_id"], f"entry {i} field 'image_id'")
        if a.ndim != 1 or a.size == 0 or a.size % 3:
            raise KeypointFormatError(
                f"{path}: entry {i} field 'keypoints' must be a flat list of 3*J numbers, found {a.shape}"
            )
        a = a.reshape(-1, 3)
        s = a[:, 2]
        if "score" not in e and np.all(np.isin(s, (0.0, 1.0, 2.0))):
            s = s / 2.0  # ground-truth visibility flags
        total = float(_numbers(path, e["score"], f"entry {i} field 'score'").sum()) if "score" in e else None
        if total is not None and not np.isfinite(total):
            raise KeypointFormatError(
                f"{path}: entry {i} field 'score': expected a number, found {e['score']!r}"
            )
        total = float(np.nansum(s)) if total is None else total
        if frame not in best or total > best[frame][2]:
            best[frame] = (a[:, :2], s, total)
    return best


def _mmpose_rows(path: Path, doc: dict) -> dict[int, tuple[np.ndarray, np.ndarray, float]]:
    best: dict[int, tuple[np.ndarray, np.ndarray, float]] = {}
    if not isinstance(doc["instance_info"], list):
        raise KeypointFormatError(
            f"{path}: field 'instance_info': expected a list of frames, found {type(doc['instance_info']).__name__}"
        )
    for i, fr in enumerate(doc["instance_info"]):
        if not isinstance(fr, dict) or not isinstance(fr.get("instances"), list):
            raise KeypointFormatError(f"{path}: instance_info[{i}] needs field 'instances' (a list)")
        frame = _frame(path, fr.get("frame_id", i), f"instance_info[{i}].frame_id")
        for k, inst in enumerate(fr["instances"]):
            where = f"instance_info[{i}].instances[{k}]"
            if not isinstance(inst, dict) or "keypoints" not in inst or "keypoint_scores" not in inst:
                raise KeypointFormatError(f"{path}: {where} needs fields 'keypoints' and 'keypoint_scores'")
            xy = _numbers(path, inst["keypoints"], f"{where}.keypoints")
            s = _numbers(path, inst["keypoint_scores"], f"{where}.keypoint_scores")
            if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] == 0 or s.shape != (xy.shape[0],):
                raise KeypointFormatError(
                    f"{path}: {where}: 'keypoints' must be (J, 2) and "
                    f"'keypoint_scores' (J,), found {xy.shape} and {s.shape}"
                )
            total = float(np.nansum(s))
            if frame not in best or total > best[frame][2]:
                best[frame] = (xy, s, total)
    return best


def read_coco(path: Path) -> Keypoints2D:
    """Read COCO keypoint results or MMPose predictions (one camera).

    Raises:
        KeypointFormatError: Unknown layout, missing fields, or joint counts that change.
    """
    path = Path(path)
    doc = read_json(path)
    names = None
    if isinstance(doc, dict) and "instance_info" in doc:
        rows = _mmpose_rows(path, doc)
        meta = doc.get("meta_info")
        id2name = meta.get("keypoint_id2name") if isinstance(meta, dict) else None
        if isinstance(id2name, dict) and all(str(k).isdigit() for k in id2name):
            names = tuple(str(id2name[k]) for k in sorted(id2name, key=int))
    elif isinstance(doc, dict) and isinstance(doc.get("annotations"), list):
        rows = _coco_rows(path, doc["annotations"])
    elif isinstance(doc, list):
        rows = _coco_rows(path, doc)
    else:
        raise KeypointFormatError(
            f"{path}: expected a COCO results list, a COCO dict with 'annotations', or MMPose predictions "
            f"with 'instance_info'; found {type(doc).__name__}"
        )
    if not rows:
        raise NoDetectionsError(f"{path}: no detections in the file")
    frames = sorted(rows)
    counts = {rows[f][0].shape[0] for f in frames}
    if len(counts) != 1:
        raise KeypointFormatError(f"{path}: field 'keypoints' has differing joint counts {sorted(counts)}")
    j = counts.pop()
    kset, default_names = keypoint_set_for(j)
    if names is None or len(names) != j:
        names = default_names
    xy = np.stack([rows[f][0] for f in frames])
    score = np.stack([rows[f][1] for f in frames])
    found = score > 0
    return Keypoints2D(
        xy=np.where(found[..., None], xy, np.nan),
        score=np.where(found, np.clip(score, 0.0, 1.0), np.nan),
        frame=np.asarray(frames, dtype=np.int64),
        joint_names=names,
        keypoint_set=kset,
        source=str(path),
        fmt="coco",
    )


def write_coco(kp: Keypoints2D, path: Path) -> Path:
    """Write ``kp`` as a COCO results list (``image_id`` = frame number; missing joints ``0, 0, 0``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = []
    for f, xy, sc in zip(kp.frame.tolist(), kp.xy, kp.score, strict=True):
        found = np.isfinite(sc)
        if not found.any():
            continue
        flat = np.stack(
            [np.where(found, xy[:, 0], 0.0), np.where(found, xy[:, 1], 0.0), np.where(found, sc, 0.0)], 1
        )
        out.append(
            {
                "image_id": f,
                "category_id": 1,
                "keypoints": flat.ravel().tolist(),
                "score": float(np.mean(sc[found])),
            }
        )
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(out))
    os.replace(tmp, path)
    return path
