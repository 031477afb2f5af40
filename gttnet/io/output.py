"""Writer of reconstructions to HDF5 or NPZ files (the "Reconstruction outputs" layout of docs/FORMAT.md)."""

from __future__ import annotations

import io
import json
from pathlib import Path

import h5py
import numpy as np

from gttdata.fileio import write_bytes_atomic, write_error
from gttnet.methods import Reconstruction

__all__ = ["OUTPUT_VERSION", "write_reconstruction", "read_reconstruction"]

#: Version of the output layout, stored as attribute ``format_version``.
OUTPUT_VERSION = 1


def _payload(rec: Reconstruction, image_index: np.ndarray | None) -> tuple[dict, dict]:
    n = rec.n_images
    index = np.arange(n) if image_index is None else np.asarray(image_index, dtype=np.int64)
    if index.shape != (n,):
        raise ValueError(f"image_index must have shape ({n},), got {index.shape}")
    arrays = {"points3d": rec.points3d.astype(np.float64), "image_index": index.astype(np.int64)}
    if rec.affinity is not None:
        arrays["affinity"] = rec.affinity.astype(np.float64)
    if rec.order is not None:
        arrays["order"] = rec.order.astype(np.int64)
    if rec.uncertainty_mm is not None:
        arrays["joint_uncertainty_mm"] = np.asarray(rec.uncertainty_mm, dtype=np.float64)
    attrs = {
        "format_version": OUTPUT_VERSION,
        "method": rec.method,
        "sequencing": rec.sequencing,
        "seconds": float(rec.seconds),
        "units": "m",
        "n_images": n,
        "n_joints": rec.n_joints,
        "info": json.dumps(rec.info, default=float),
    }
    return arrays, attrs


def write_reconstruction(
    rec: Reconstruction,
    path: str | Path,
    *,
    image_index: np.ndarray | None = None,
    source: str = "",
    extra: dict[str, np.ndarray] | None = None,
    extra_attrs: dict[str, str] | None = None,
) -> Path:
    """Write a reconstruction; the suffix picks the container (``.h5``/``.hdf5`` or ``.npz``).

    Written atomically (in memory, then temporary file, fsync, rename); a failed write raises one
    :class:`~gttdata.errors.OutputError` line naming ``path``. Contents: ``points3d`` (N, J, 3) float64 metres,
    ``image_index`` (N,) int64 (stored index in the input file of each row), ``affinity`` (N, N) and
    ``order`` (N,) when the method produced them, ``joint_uncertainty_mm`` (N, J) float64 millimetres when
    the reconstruction was self-assessed (:mod:`gttnet.quality`); attributes ``format_version``, ``method``,
    ``sequencing``, ``seconds``, ``units`` (``"m"``), ``n_images``, ``n_joints``, ``info`` (JSON) and
    ``source``. In NPZ files the attributes are 0-d arrays of the same names.

    Args:
        rec: The reconstruction.
        path: Output file.
        image_index: Stored index of each image in the input file, shape ``(N,)`` (default: identity).
        source: Input file name, recorded as an attribute.
        extra: More per-image arrays (recordings add ``cam_id`` (N,), ``frame`` (N,), ``time_s`` (N,)
            seconds, NaN when unknown, and ``time_order`` (N,), the rows in time order).
        extra_attrs: More string attributes (recordings add ``camera_names`` (JSON list) and
            ``recording`` (the recording spec as JSON, which ``gttnet render`` reloads)).

    Returns:
        The path written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in (".h5", ".hdf5", ".npz"):
        raise ValueError(f"{path}: output suffix must be .h5, .hdf5 or .npz, got {suffix!r}")
    arrays, attrs = _payload(rec, image_index)
    attrs["source"] = source
    for k, v in (extra or {}).items():
        arrays[k] = np.asarray(v)
    attrs.update(extra_attrs or {})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)  # --out runs/rec.h5 on a fresh checkout
    except OSError as exc:
        raise write_error(path.parent, exc) from exc
    # Built in memory, then written in one piece: HDF5 never meets a disk error (a full disk crashed it
    # with a segfault), and a failed write is one line naming the path, with no temporary file left.
    buf = io.BytesIO()
    if suffix == ".npz":
        np.savez_compressed(buf, **{**arrays, **{k: np.asarray(v) for k, v in attrs.items()}})
    else:
        with h5py.File(buf, "w") as f:
            for k, v in arrays.items():
                f.create_dataset(k, data=v, compression="gzip" if v.size > 4096 else None)
            for k, v in attrs.items():
                f.attrs[k] = v
    write_bytes_atomic(path, buf.getbuffer())
    return path


def read_reconstruction(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Read back a file written by :func:`write_reconstruction`.

    Returns:
        ``(arrays, attrs)``: the datasets by name and the attributes (``info`` parsed from JSON).
    """
    path = Path(path)
    names = (
        "points3d",
        "image_index",
        "affinity",
        "order",
        "joint_uncertainty_mm",
        "cam_id",
        "frame",
        "time_s",
        "time_order",
    )
    if path.suffix.lower() == ".npz":
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in names if k in z.files}
            attrs = {k: z[k].item() for k in z.files if k not in names}
    else:
        with h5py.File(path, "r") as f:
            arrays = {k: f[k][()] for k in names if k in f}
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    attrs["info"] = json.loads(attrs.get("info", "{}"))
    return arrays, attrs
