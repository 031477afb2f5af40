"""SLEAP ``.slp`` predictions, one file per camera, read through ``sleap-io``.

``sleap-io`` installs from PyPI without torch but brings about 0.5 GB of dependencies (NWB, skia,
an ffmpeg binary...), so it is an optional extra: ``pip install "gtt[sleap]"``. Without it the reader
stops with one line saying so. The first video of the file is read; per frame the instance with the
highest summed point score is kept (one subject per capture); user-labelled instances count with
score 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gttdata.detectors import Keypoints2D
from gttdata.errors import KeypointFormatError, NoDetectionsError

__all__ = ["SUMMARY", "read_sleap"]

SUMMARY = "SLEAP .slp predictions, one per camera (needs the optional sleap-io: pip install 'gtt[sleap]')"


def _points(path: Path, inst: object, frame: int, n_nodes: int) -> np.ndarray:
    """One instance's ``(J, 3)`` array of x, y and score (user-labelled points score 1)."""
    scored = hasattr(inst, "score")  # PredictedInstance: x, y, point score
    try:
        a = np.asarray(inst.numpy(scores=True) if scored else inst.numpy(), dtype=np.float64)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as exc:
        raise KeypointFormatError(
            f"{path}: frame {frame}: an instance's points are not numbers ({exc})"
        ) from exc
    cols = 3 if scored else 2
    if a.shape != (n_nodes, cols):
        raise KeypointFormatError(
            f"{path}: frame {frame}: an instance has points of shape {a.shape}, expected ({n_nodes}, {cols}) "
            f"for the skeleton's {n_nodes} nodes"
        )
    if not scored:
        a = np.concatenate([a, np.where(np.isfinite(a[:, :1]), 1.0, np.nan)], axis=1)
    return a


def read_sleap(path: Path) -> Keypoints2D:
    """Read SLEAP predictions (one camera) with ``sleap_io.load_slp``.

    Raises:
        KeypointFormatError: sleap-io missing, an unreadable file, or no labelled frames.
    """
    path = Path(path)
    try:
        import sleap_io as sio
    except ModuleNotFoundError as exc:
        raise KeypointFormatError(
            f"{path}: reading SLEAP files needs sleap-io (pip install 'gtt[sleap]'); it is not installed"
        ) from exc
    try:
        labels = sio.load_slp(str(path))
    except Exception as exc:  # sleap-io raises many types for a bad file; one line names it
        raise KeypointFormatError(f"{path}: sleap-io cannot read the file: {exc}") from exc
    if not labels.skeletons or not labels.videos:
        raise KeypointFormatError(f"{path}: the file has no skeleton or no video")
    names = tuple(str(n) for n in labels.skeletons[0].node_names)
    video = labels.videos[0]
    rows: dict[int, tuple[np.ndarray, float]] = {}
    for lf in labels.labeled_frames:
        if lf.video is not video:
            continue
        f = lf.frame_idx
        if isinstance(f, bool) or not isinstance(f, int | np.integer) or not 0 <= f < 2**62:
            raise KeypointFormatError(
                f"{path}: a labelled frame's frame_idx must be an integer >= 0, found {f!r}"
            )
        for inst in lf.instances:
            a = _points(path, inst, int(f), len(names))
            total = float(np.nansum(a[:, 2]))
            if int(f) not in rows or total > rows[int(f)][1]:
                rows[int(f)] = (a, total)
    if not rows:
        raise NoDetectionsError(f"{path}: no labelled frames for video {video.filename!r}")
    frames = sorted(rows)
    a = np.stack([rows[f][0] for f in frames])
    return Keypoints2D(
        xy=a[..., :2],
        score=np.clip(a[..., 2], 0.0, 1.0),
        frame=np.asarray(frames, dtype=np.int64),
        joint_names=names,
        source=str(path),
        fmt="sleap",
    )
