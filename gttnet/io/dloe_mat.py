"""Importer of the DLOE MATLAB demo layout (a ``caminput`` struct of per-image cells, optional X_GT)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import scipy.io

from gttdata.skeleton import default_skeleton
from gttnet.errors import ImportFormatError
from gttnet.io._views import UNITS, ImportedCapture, resolve_units

__all__ = ["read_dloe_mat"]

log = logging.getLogger(__name__)


def _load(path: Path) -> dict:
    try:
        return scipy.io.loadmat(str(path), squeeze_me=False, struct_as_record=True)
    except FileNotFoundError:
        raise
    except Exception as exc:  # noqa: BLE001 - scipy raises MatReadError, ValueError, TypeError... on bad files
        size = path.stat().st_size if path.exists() else 0
        found = "an empty file" if size == 0 else f"{size} bytes it cannot read ({exc})"
        raise ImportFormatError(f"{path}: expected a MATLAB .mat file (v5/v7), found {found}") from exc


def _struct_field(path: Path, struct: np.ndarray, name: str, *, optional: bool = False):
    if struct.dtype.names is None or name not in struct.dtype.names:
        if optional:
            return None
        have = ", ".join(struct.dtype.names or ())
        raise ImportFormatError(
            f"{path}: field 'caminput.{name}': expected a field of caminput, found only {have}"
        )
    return struct[name].flat[0]


def _numeric(path: Path, value, name: str) -> np.ndarray:
    """``value`` as a float64 array; a string, struct or ragged cell is one line naming the field."""
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ImportFormatError(
            f"{path}: field '{name}': expected numbers, found {type(value).__name__} ({exc})"
        ) from exc


def _cells(path: Path, value, name: str, n: int | None, shape: tuple[int | None, ...]) -> list[np.ndarray]:
    """A cell array as a list of float arrays of the given shape (None = any size)."""
    if not (isinstance(value, np.ndarray) and value.dtype == object):
        raise ImportFormatError(
            f"{path}: field 'caminput.{name}': expected an N x 1 cell array, found {type(value).__name__}"
        )
    items = [_numeric(path, v, f"caminput.{name}{{{i + 1}}}") for i, v in enumerate(value.ravel())]
    if n is not None and len(items) != n:
        raise ImportFormatError(
            f"{path}: field 'caminput.{name}': expected {n} cells (one per image), found {len(items)}"
        )
    for i, a in enumerate(items):
        if a.ndim != len(shape) or any(s is not None and s != g for s, g in zip(shape, a.shape, strict=True)):
            want = " x ".join("P" if s is None else str(s) for s in shape)
            raise ImportFormatError(
                f"{path}: field 'caminput.{name}{{{i + 1}}}': expected a {want} array, found shape {a.shape}"
            )
    return items


def _order(path: Path, value, n: int, name: str) -> np.ndarray | None:
    """A 1-based global order (a sequence of image numbers) as the time rank of each image, or None."""
    if value is None:
        return None
    a = _numeric(path, value, name).ravel()
    if a.size == 1 and a[0] == 0:
        return None
    if a.size != n or not np.array_equal(np.sort(a), np.arange(1, n + 1)):
        raise ImportFormatError(
            f"{path}: field '{name}': expected 0 or a 1 x {n} permutation of 1..{n}, found {a.size} values"
        )
    rank = np.empty(n, dtype=np.int64)
    rank[a.astype(np.int64) - 1] = np.arange(n)
    return rank


def _cameras(path: Path, cam_index: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    counts = _numeric(path, cam_index, "caminput.cam_index").ravel()
    if (
        counts.size == 0
        or not np.all(np.isfinite(counts))
        or np.any(counts != np.round(counts))
        or np.any(np.diff(np.concatenate([[0.0], counts])) <= 0)
        or counts[-1] != n
    ):
        raise ImportFormatError(
            f"{path}: field 'caminput.cam_index': expected 1 x V increasing cumulative image counts ending at "
            f"N = {n}, found {counts.tolist()[:8]}"
        )
    bounds = np.concatenate([[0], counts.astype(np.int64)])
    cam = np.repeat(np.arange(counts.size), np.diff(bounds)).astype(np.int32)
    stream = (np.arange(n) - bounds[cam]).astype(np.int32)
    return cam, stream


def read_dloe_mat(path: str | Path, *, units: str | None = None) -> ImportedCapture:
    """Read a DLOE demo ``.mat`` file.

    Layout (docs/FORMAT.md, "DLOE MATLAB layout"): a struct ``caminput`` with ``x`` (N x 1 cell of 3 x P homogeneous pixel
    coordinates, NaN for a missing joint), ``K`` (N x 1 cell of 3 x 3), ``R`` (N x 1 cell of
    world→camera rotations), ``t`` (N x 1 cell of 1 x 3 camera **centres**), ``cam_index`` (1 x V
    cumulative image counts; images grouped by camera and time-ordered inside each) and ``order`` (0, or
    a 1 x N 1-based sequence of image numbers in time order). Optional top level: ``X_GT`` (3P x N,
    joint-major rows: rows 3p..3p+2 hold joint p) and ``order`` (used when ``caminput.order`` is 0).

    Lengths are converted from ``units`` to metres; the world frame stays the file's (y up in the demos).
    Image sizes are not stored: each camera's is taken as twice its principal point.

    Args:
        path: The ``.mat`` file.
        units: Length unit of the file (key of :data:`gttnet.io._views.UNITS`); the layout records none
            (the demos are in inches), so None assumes metres with a warning.

    Returns:
        The capture in file order.

    Raises:
        ImportFormatError: Naming the file, the field, what was expected and what was found.
    """
    path = Path(path)
    units = resolve_units(path, "dloe-mat", units)
    scale = UNITS[units]
    mat = _load(path)
    if "caminput" not in mat:
        have = ", ".join(k for k in mat if not k.startswith("__"))
        raise ImportFormatError(
            f"{path}: field 'caminput': expected a struct, found only variables {have or 'none'}"
        )
    ci = mat["caminput"]
    if ci.dtype.names is None:
        raise ImportFormatError(f"{path}: field 'caminput': expected a struct, found {ci.dtype}")
    x = _cells(path, _struct_field(path, ci, "x"), "x", None, (3, None))
    n = len(x)
    if n == 0:
        raise ImportFormatError(f"{path}: field 'caminput.x': expected at least one image, found 0")
    p = x[0].shape[1]
    x = _cells(path, _struct_field(path, ci, "x"), "x", n, (3, p))
    K = np.stack(_cells(path, _struct_field(path, ci, "K"), "K", n, (3, 3)))
    R = np.stack(_cells(path, _struct_field(path, ci, "R"), "R", n, (3, 3)))
    t_cells = _cells(path, _struct_field(path, ci, "t"), "t", n, (None, None))
    sizes = sorted({c.size for c in t_cells})
    if sizes != [3]:
        raise ImportFormatError(
            f"{path}: field 'caminput.t': expected N cells of 1 x 3 centres, found cells of {sizes} values"
        )
    centres = np.stack([c.ravel() for c in t_cells])
    cam, stream = _cameras(path, _struct_field(path, ci, "cam_index"), n)
    rank = _order(path, _struct_field(path, ci, "order", optional=True), n, "caminput.order")
    if rank is None and "order" in mat:
        rank = _order(path, mat["order"], n, "order")
    h = np.stack(x)  # (N, 3, P)
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.transpose(h[:, :2] / h[:, 2:3], (0, 2, 1))
    visible = np.all(np.isfinite(px), axis=-1)
    px[~visible] = np.nan
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = -np.einsum("nab,nb->na", R, centres * scale)
    first = np.searchsorted(cam, np.arange(cam.max() + 1))
    image_size = np.round(2.0 * K[first][:, :2, 2]).astype(np.int32)
    X = None
    if "X_GT" in mat:
        gt = _numeric(path, mat["X_GT"], "X_GT")
        if gt.shape != (3 * p, n):
            raise ImportFormatError(
                f"{path}: field 'X_GT': expected shape (3P, N) = {(3 * p, n)}, found {gt.shape}"
            )
        X = gt.reshape(p, 3, n).transpose(2, 0, 1) * scale  # joint-major rows -> (N, P, 3)
    log.info("%s: %d images, %d joints, %d cameras (units %s)", path, n, p, cam.max() + 1, units)
    return ImportedCapture(
        source=str(path),
        skeleton=default_skeleton(p, "imported"),
        cam_id=cam,
        stream_index=stream,
        K=K,
        cam_from_world=T,
        keypoints_px=px,
        visible=visible,
        image_size=image_size,
        time_rank=rank,
        points3d=X,
        file_units=units,
    )
