"""DeepLabCut predictions: one ``.csv`` or ``.h5`` file per camera video.

The CSV has three header rows (``scorer``, ``bodyparts``, ``coords`` with ``x, y, likelihood`` per
body part), four for multi-animal projects (an ``individuals`` row after ``scorer``; the first
individual is read), then one row per frame whose first cell is the frame number (or an image path,
then rows are numbered in order). The ``.h5`` file is the same table stored by pandas under the key
``df_with_missing`` (``format="table"`` as DeepLabCut writes it, or ``"fixed"``). It is read with h5py
alone (:mod:`gttdata.detectors.pandas_h5`), never with ``pandas.read_hdf``, which unpickles object
columns and attributes: a keypoint file cannot run code. Writing ``.h5`` needs pandas and PyTables
(``pip install "gtt[formats]"``).
DeepLabCut predicts every body part in every frame: low ``likelihood`` marks the unreliable ones,
NaN coordinates the absent ones.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from gttdata.detectors import Keypoints2D
from gttdata.detectors.pandas_h5 import read_pandas_frame
from gttdata.errors import KeypointFormatError, NoDetectionsError

__all__ = ["SUMMARY", "read_dlc", "write_dlc"]

SUMMARY = "DeepLabCut predictions, one .csv or .h5 per camera (x, y, likelihood per body part)"

_SCORER = "DLC_gtt_export"


def _frames_from_index(path: Path, index: list[str], first_line: int) -> np.ndarray:
    """Frame number of each row: the first cell when every row's is a whole number, else the row order.

    Image paths (``labeled-data/...``) number the rows in order; a number that is not a whole number
    ``>= 0`` (``-1``, ``2.5``, ``inf``) is one line naming it.
    """
    try:
        values = [float(v) for v in index]
    except ValueError:
        return np.arange(len(index), dtype=np.int64)  # image paths (labeled-data/...): row order
    for i, v in enumerate(values):
        if not (np.isfinite(v) and v >= 0 and v.is_integer() and v < 2**62):
            raise KeypointFormatError(
                f"{path}: line {first_line + i}: expected a frame number (an integer >= 0) in the first "
                f"column, found {index[i]!r}"
            )
    return np.asarray(values, dtype=np.int64)


def _assemble(
    path: Path,
    bodyparts: list[str],
    coords: list[str],
    data: np.ndarray,
    index: list[str],
    first_line: int = 1,
):
    parts: list[str] = []
    for b in bodyparts:
        if b not in parts:
            parts.append(b)
    col = {(b, c): i for i, (b, c) in enumerate(zip(bodyparts, coords, strict=True))}
    xy = np.full((data.shape[0], len(parts), 2), np.nan)
    score = np.full((data.shape[0], len(parts)), np.nan)
    for j, b in enumerate(parts):
        for c in ("x", "y", "likelihood"):
            if (b, c) not in col:
                raise KeypointFormatError(
                    f"{path}: body part {b!r} has no {c!r} column in the 'coords' header"
                )
        xy[:, j, 0] = data[:, col[(b, "x")]]
        xy[:, j, 1] = data[:, col[(b, "y")]]
        score[:, j] = data[:, col[(b, "likelihood")]]
    return Keypoints2D(
        xy=xy,
        score=np.clip(score, 0.0, 1.0),
        frame=_frames_from_index(path, index, first_line),
        joint_names=tuple(parts),
        source=str(path),
        fmt="dlc",
    )


def _first_individual(header: dict[str, list[str]]) -> np.ndarray:
    ind = header.get("individuals")
    if ind is None:
        return np.ones(len(header["bodyparts"]), dtype=bool)
    return np.asarray([v == ind[0] for v in ind])


def _read_csv(path: Path) -> Keypoints2D:
    try:
        rows = list(csv.reader(io.StringIO(path.read_text())))
    except (csv.Error, UnicodeDecodeError) as exc:
        raise KeypointFormatError(f"{path}: not a DeepLabCut CSV file: {exc}") from exc
    header: dict[str, list[str]] = {}
    k = 0
    while k < len(rows) and rows[k] and rows[k][0] in ("scorer", "individuals", "bodyparts", "coords"):
        header[rows[k][0]] = rows[k][1:]
        k += 1
    for field in ("scorer", "bodyparts", "coords"):
        if field not in header:
            raise KeypointFormatError(f"{path}: DeepLabCut header row {field!r} is missing")
    ncol = len(header["coords"])
    if len(header["bodyparts"]) != ncol:
        raise KeypointFormatError(
            f"{path}: header 'bodyparts' has {len(header['bodyparts'])} columns, 'coords' has {ncol}"
        )
    body = [r for r in rows[k:] if r]
    if not body:
        raise NoDetectionsError(f"{path}: no prediction rows after the header")
    data = np.full((len(body), ncol), np.nan)
    for i, r in enumerate(body):
        if len(r) != ncol + 1:
            raise KeypointFormatError(f"{path}: line {k + i + 1} has {len(r) - 1} values, expected {ncol}")
        try:
            data[i] = [float(v) if v.strip() else np.nan for v in r[1:]]
        except ValueError as exc:
            raise KeypointFormatError(f"{path}: line {k + i + 1}: {exc}") from exc
    keep = _first_individual(header)
    return _assemble(
        path,
        [b for b, m in zip(header["bodyparts"], keep, strict=True) if m],
        [c for c, m in zip(header["coords"], keep, strict=True) if m],
        data[:, keep],
        [r[0] for r in body],
        k + 1,
    )


def _pandas():
    try:
        import pandas as pd
    except ModuleNotFoundError as exc:
        raise KeypointFormatError(
            "DeepLabCut .h5 files are pandas tables: install pandas and tables (pip install 'gtt[formats]') "
            "or export the predictions as .csv"
        ) from exc
    return pd


def _read_h5(path: Path) -> Keypoints2D:
    frame = read_pandas_frame(path, "df_with_missing" if _has_key(path, "df_with_missing") else None)
    names = list(frame.names)
    if "bodyparts" not in names or "coords" not in names:
        raise KeypointFormatError(
            f"{path}: column levels must include 'bodyparts' and 'coords', found {names}"
        )
    cols = frame.columns
    keep = np.ones(len(cols), dtype=bool)
    if "individuals" in names:
        level = names.index("individuals")
        keep = np.asarray([c[level] == cols[0][level] for c in cols]) if cols else keep
    b, c = names.index("bodyparts"), names.index("coords")
    return _assemble(
        path,
        [str(col[b]) for col, m in zip(cols, keep, strict=True) if m],
        [str(col[c]) for col, m in zip(cols, keep, strict=True) if m],
        frame.values[:, keep],
        frame.index,
    )


def _has_key(path: Path, key: str) -> bool:
    import h5py

    try:
        with h5py.File(path, "r") as fh:
            return key in fh
    except OSError:
        return False  # read_pandas_frame names the file and the reason


def read_dlc(path: Path) -> Keypoints2D:
    """Read DeepLabCut predictions (``.csv`` or ``.h5``) of one camera.

    Raises:
        KeypointFormatError: Missing header rows or columns, ragged rows, non-numeric values.
    """
    path = Path(path)
    if path.suffix.lower() == ".csv":
        return _read_csv(path)
    return _read_h5(path)


def write_dlc(kp: Keypoints2D, path: Path) -> Path:
    """Write ``kp`` as DeepLabCut predictions; the suffix picks ``.csv`` or ``.h5``.

    Coordinates are written at full precision (``repr`` of each float); missing joints get NaN
    coordinates and likelihood 0.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    n, j = kp.score.shape
    data = np.empty((n, 3 * j))
    data[:, 0::3] = kp.xy[..., 0]
    data[:, 1::3] = kp.xy[..., 1]
    data[:, 2::3] = np.nan_to_num(kp.score, nan=0.0)
    parts = [b for b in kp.joint_names for _ in range(3)]
    coords = ["x", "y", "likelihood"] * j
    if path.suffix.lower() == ".csv":
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["scorer"] + [_SCORER] * (3 * j))
        w.writerow(["bodyparts"] + parts)
        w.writerow(["coords"] + coords)
        for f, row in zip(kp.frame.tolist(), data, strict=True):
            w.writerow([str(f)] + ["" if np.isnan(v) else repr(float(v)) for v in row])
        tmp.write_text(buf.getvalue())
    elif path.suffix.lower() in (".h5", ".hdf5"):
        pd = _pandas()
        columns = pd.MultiIndex.from_arrays(
            [[_SCORER] * (3 * j), parts, coords], names=["scorer", "bodyparts", "coords"]
        )
        df = pd.DataFrame(data, columns=columns, index=kp.frame)
        df.to_hdf(tmp, key="df_with_missing", format="table", mode="w")
    else:
        raise ValueError(f"{path}: a DeepLabCut file must end in .csv or .h5")
    os.replace(tmp, path)
    return path
