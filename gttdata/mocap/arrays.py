"""NumPy ``.npz`` and HDF5 motion files: positions with their skeleton, loaded and saved.

Layout (both formats; HDF5 keeps ``fps_hz``, ``units`` and ``name`` as root attributes or datasets):
    * ``positions``: float, shape ``(T, J, 3)``, world z-up (no axis conversion is applied).
    * ``fps_hz``: scalar, Hz.
    * ``joint_names``: strings, length J.
    * ``parents``: ints, length J (-1 for roots; the parents form a forest).
    * optional ``units``: ``"m"`` (default), ``"cm"`` or ``"mm"``; converted to metres on load.
    * optional ``mirror`` (ints, length J), ``extra_bones`` (ints, shape ``(E, 2)``), ``skeleton_name`` and
      ``name``; written by :func:`save_motion`.
"""

from __future__ import annotations

import json
import logging
import math
import zipfile
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from gttdata.errors import MotionFormatError
from gttdata.mocap import register_loader
from gttdata.mocap.motion import Motion
from gttdata.skeleton import CMU31_JOINTS, Skeleton, cmu31

__all__ = ["load_hdf5", "load_npz", "save_motion"]

_log = logging.getLogger(__name__)

_UNITS_M = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_REQUIRED = ("positions", "fps_hz", "joint_names", "parents")


def _as_str(v) -> str:
    if isinstance(v, bytes):
        return v.decode()
    if isinstance(v, np.ndarray):
        return _as_str(v.item()) if v.shape == () else str(v)
    return str(v)


def _build(path: Path, fmt: str, fields: dict) -> Motion:
    """Validate raw fields (as read) and build the Motion; errors name the field."""
    for key in _REQUIRED:
        if key not in fields:
            raise MotionFormatError(f"{path}: field {key!r} is missing; expected {', '.join(_REQUIRED)}")
    try:
        pos = np.asarray(fields["positions"], dtype=np.float64)
    except (TypeError, ValueError):
        raise MotionFormatError(
            f"{path}: field 'positions' must be numeric, found {fields['positions'].dtype}"
        ) from None
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise MotionFormatError(f"{path}: field 'positions' must have shape (T, J, 3), found {pos.shape}")
    if pos.shape[0] == 0:
        raise MotionFormatError(f"{path}: field 'positions' has zero frames; expected at least 1")
    if not np.all(np.isfinite(pos)):
        t, j = np.argwhere(~np.all(np.isfinite(pos), axis=-1))[0]
        raise MotionFormatError(
            f"{path}: field 'positions' must be finite, found {pos[t, j].tolist()} at frame {t}, joint {j}"
        )
    try:
        fps = float(np.asarray(fields["fps_hz"]).reshape(()))
    except (TypeError, ValueError):
        raise MotionFormatError(
            f"{path}: field 'fps_hz' must be one number, found {fields['fps_hz']!r}"
        ) from None
    if not (math.isfinite(fps) and fps > 0):
        raise MotionFormatError(f"{path}: field 'fps_hz' must be > 0, found {fps}")
    names = tuple(_as_str(n) for n in np.asarray(fields["joint_names"]).ravel())
    try:
        parents = tuple(int(p) for p in np.asarray(fields["parents"]).ravel())
    except (TypeError, ValueError):
        raise MotionFormatError(
            f"{path}: field 'parents' must be integers, found {fields['parents']!r}"
        ) from None
    units = _as_str(fields.get("units", "m"))
    if units not in _UNITS_M:
        raise MotionFormatError(f"{path}: field 'units' must be one of {sorted(_UNITS_M)}, found {units!r}")
    if len(names) != pos.shape[1] or len(parents) != pos.shape[1]:
        raise MotionFormatError(
            f"{path}: fields 'joint_names' and 'parents' must have length J = {pos.shape[1]} (positions), "
            f"found {len(names)} and {len(parents)}"
        )
    skeleton = _skeleton(path, fields, names, parents)
    return Motion(
        positions=pos * _UNITS_M[units],
        fps_hz=fps,
        skeleton=skeleton,
        name=_as_str(fields.get("name", path.stem)),
        provenance={"path": str(path), "format": fmt, "units": units},
    )


def _skeleton(path: Path, fields: dict, names: tuple[str, ...], parents: tuple[int, ...]) -> Skeleton:
    sk_name = _as_str(fields.get("skeleton_name", path.stem))
    mirror = tuple(int(m) for m in np.asarray(fields.get("mirror", ())).ravel())
    extra = tuple(
        (int(a), int(b)) for a, b in np.asarray(fields.get("extra_bones", ()), dtype=np.int64).reshape(-1, 2)
    )
    if names == CMU31_JOINTS and (sk_name == "cmu31" or "skeleton_name" not in fields):
        cmu = cmu31()
        if parents == cmu.parents and mirror in ((), cmu.mirror):
            return cmu
    try:
        return Skeleton(name=sk_name, joint_names=names, parents=parents, mirror=mirror, extra_bones=extra)
    except ValueError as exc:
        if "mirror" in str(exc) and not mirror:
            return Skeleton(sk_name, names, parents, mirror=tuple(range(len(names))), extra_bones=extra)
        raise MotionFormatError(f"{path}: fields 'joint_names'/'parents'/'mirror': {exc}") from None


@register_loader("npz", suffixes=(".npz",))
def load_npz(path: str | Path) -> Motion:
    """Load a ``.npz`` motion (layout in the module docstring).

    Returns:
        Motion with ``positions`` of shape ``(T, J, 3)`` in metres, world z-up.

    Raises:
        MotionFormatError: Missing field, wrong shape, non-finite values, zero frames, bad skeleton.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            fields = {k: z[k] for k in z.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise MotionFormatError(f"{path}: not a readable .npz archive ({exc})") from exc
    return _build(path, "npz", fields)


@register_loader("hdf5", suffixes=(".h5", ".hdf5"))
def load_hdf5(path: str | Path) -> Motion:
    """Load an HDF5 motion (datasets as in the module docstring; scalars may be root attributes).

    Returns:
        Motion with ``positions`` of shape ``(T, J, 3)`` in metres, world z-up.

    Raises:
        MotionFormatError: Missing field, wrong shape, non-finite values, zero frames, bad skeleton.
    """
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            fields = {k: v for k, v in f.attrs.items()}
            for k, ds in f.items():
                if isinstance(ds, h5py.Dataset):
                    fields[k] = ds[()]
    except OSError as exc:
        raise MotionFormatError(f"{path}: not a readable HDF5 file ({exc})") from exc
    return _build(path, "hdf5", fields)


def save_motion(motion: Motion, path: str | Path) -> Path:
    """Write ``motion`` as ``.npz`` or ``.h5``/``.hdf5`` (by suffix), in metres; inverse of the loaders.

    Args:
        motion: The motion; its positions (T, J, 3) are written in metres, world z-up.
        path: Output file; written to a temporary name, then renamed.

    Returns:
        The path written.
    """
    path = Path(path)
    sk = motion.skeleton
    fields: dict[str, Any] = {
        "positions": motion.positions,
        "fps_hz": np.float64(motion.fps_hz),
        "joint_names": np.array(sk.joint_names, dtype=str),
        "parents": np.array(sk.parents, dtype=np.int64),
        "mirror": np.array(sk.mirror, dtype=np.int64),
        "extra_bones": np.array(sk.extra_bones, dtype=np.int64).reshape(-1, 2),
        "units": "m",
        "skeleton_name": sk.name,
        "name": motion.name,
    }
    tmp = path.with_name(path.name + ".tmp")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        with tmp.open("wb") as fh:
            np.savez_compressed(fh, **fields)
    elif suffix in (".h5", ".hdf5"):
        with h5py.File(tmp, "w") as f:
            for k in ("positions", "parents", "mirror", "extra_bones"):
                f.create_dataset(k, data=fields[k])
            f.create_dataset(
                "joint_names", data=np.array(sk.joint_names, dtype=object), dtype=h5py.string_dtype()
            )
            for k in ("fps_hz", "units", "skeleton_name", "name"):
                f.attrs[k] = fields[k]
            f.attrs["provenance"] = json.dumps(motion.provenance, default=str)
    else:
        raise MotionFormatError(
            f"{path}: save_motion expects a .npz, .h5 or .hdf5 suffix, found {path.suffix!r}"
        )
    tmp.replace(path)
    _log.debug("wrote %s (%d frames)", path, motion.n_frames)
    return path
