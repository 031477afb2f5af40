"""C3D marker loader (via the ``c3d`` package): each labelled marker becomes one root joint.

Conventions:
    * Joints are the markers, named by their ``POINT:LABELS`` (a subject prefix shared by every
      label, such as ``Nick01:``, is stripped); every parent is -1 (markers have no hierarchy).
    * Units from ``POINT:UNITS`` (``mm``, ``cm`` or ``m``) are converted to metres.
    * A sample with a negative residual is missing (the ``c3d`` package also reads non-finite
      coordinates that way); gaps are filled by linear interpolation over
      time (the nearest valid sample is held before the first and after the last). A marker
      missing in every frame is dropped with a warning.
    * Axes: C3D has no fixed up axis. ``up_axis="auto"`` picks the axis along which the markers'
      per-frame spread is largest (a standing body is taller than it is wide), assumed positive;
      :func:`to_z_up` then rotates it onto +z (right-handed).
"""

from __future__ import annotations

import logging
import math
import struct
import warnings
from pathlib import Path

import numpy as np

from gttdata.errors import MotionFormatError
from gttdata.mocap import register_loader
from gttdata.mocap.motion import Motion
from gttdata.skeleton import Skeleton

__all__ = ["load_c3d", "read_c3d_points", "to_z_up"]

_log = logging.getLogger(__name__)

_UNITS_M = {"mm": 1e-3, "cm": 1e-2, "m": 1.0, "dm": 0.1}


def to_z_up(positions: np.ndarray, up_axis: str) -> np.ndarray:
    """Rotate axes so that ``up_axis`` becomes +z, keeping a right-handed frame.

    Args:
        positions: Points in the file's axes, shape ``(..., 3)``.
        up_axis: ``"x"``, ``"y"`` or ``"z"``.

    Returns:
        Points in world axes, shape ``(..., 3)``: up ``y`` maps ``(x, y, z) -> (x, -z, y)`` (a +90
        degree turn about x, as the BVH and ASF loaders do), up ``x`` maps ``(x, y, z) -> (y, z, x)``.

    Example:
        >>> to_z_up(np.array([1.0, 2.0, 3.0]), "y").tolist()
        [1.0, -3.0, 2.0]
    """
    p = np.asarray(positions, dtype=np.float64)
    if up_axis == "y":
        return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
    if up_axis == "x":
        return p[..., [1, 2, 0]]
    return p.copy()


def read_c3d_points(path: str | Path) -> tuple[np.ndarray, np.ndarray, list[str], float, str]:
    """Raw C3D points.

    Args:
        path: C3D file.

    Returns:
        ``(xyz, residual, labels, rate_hz, units)``: coordinates in file units and axes, shape
        ``(T, M, 3)``; residuals, shape ``(T, M)`` (negative = missing); stripped labels; point rate;
        ``POINT:UNITS`` as written.
    """
    import c3d  # third-party; imported here so the registry stays importable without it

    path = Path(path)
    frames = []
    with path.open("rb") as handle, warnings.catch_warnings():
        # The package warns about optional groups (analog data, descriptions) that marker files lack.
        warnings.filterwarnings("ignore", category=UserWarning, module=r"c3d.*")
        try:
            reader = c3d.Reader(handle)
            units_param = reader.get("POINT:UNITS")
            units = units_param.string_value.strip() if units_param is not None else "mm"
            labels = [str(s).strip() for s in reader.point_labels]
            rate = float(reader.point_rate)
            for _, points, _ in reader.read_frames():
                frames.append(np.array(points[:, :4], dtype=np.float64))
        except MotionFormatError:
            raise
        except (ValueError, KeyError, IndexError, OSError, AssertionError, EOFError, struct.error) as exc:
            raise MotionFormatError(f"{path}: not a readable C3D file ({type(exc).__name__}: {exc})") from exc
    if not frames:
        raise MotionFormatError(f"{path}: found zero frames; expected at least 1")
    data = np.stack(frames)
    if len(labels) < data.shape[1]:
        labels += [f"marker{i}" for i in range(len(labels), data.shape[1])]
    return data[..., :3], data[..., 3], labels[: data.shape[1]], rate, units


def _strip_prefix(labels: list[str]) -> list[str]:
    prefixes = {lab.split(":", 1)[0] for lab in labels if ":" in lab}
    if len(prefixes) == 1 and all(":" in lab for lab in labels):
        stripped = [lab.split(":", 1)[1] for lab in labels]
        if len(set(stripped)) == len(stripped):
            return stripped
    return labels


def _fill_gaps(xyz: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Linear interpolation of missing samples per marker, shape ``(T, M, 3)``."""
    out = xyz.copy()
    t = np.arange(xyz.shape[0])
    for m in np.flatnonzero(~valid.all(axis=0)):
        ok = valid[:, m]
        for c in range(3):
            out[:, m, c] = np.interp(t, t[ok], xyz[ok, m, c])
    return out


def _guess_up_axis(xyz: np.ndarray) -> str:
    spread = np.median(xyz.max(axis=1) - xyz.min(axis=1), axis=0)
    return "xyz"[int(np.argmax(spread))]


@register_loader("c3d", suffixes=(".c3d",))
def load_c3d(path: str | Path, *, up_axis: str = "auto") -> Motion:
    """Load C3D markers as a Motion of root-only joints in metres, world z-up.

    Args:
        path: C3D file.
        up_axis: ``"auto"``, ``"x"``, ``"y"`` or ``"z"``: the file's up axis (see module docstring).

    Returns:
        Motion with ``positions`` of shape ``(T, M, 3)`` in metres, world z-up, one joint per marker
        seen in at least one frame.

    Raises:
        MotionFormatError: Unreadable file, unknown units, zero frames, non-finite valid samples, or
            no marker ever seen.
    """
    path = Path(path)
    if up_axis not in ("auto", "x", "y", "z"):
        raise ValueError(f"up_axis must be 'auto', 'x', 'y' or 'z', got {up_axis!r}")
    xyz, residual, labels, rate, units = read_c3d_points(path)
    if units.lower() not in _UNITS_M:
        raise MotionFormatError(f"{path}: POINT:UNITS must be one of {sorted(_UNITS_M)}, found {units!r}")
    if not (math.isfinite(rate) and rate > 0):
        raise MotionFormatError(f"{path}: POINT:RATE must be > 0, found {rate}")
    valid = residual >= 0
    bad = valid & ~np.all(np.isfinite(xyz), axis=-1)
    if bad.any():
        t, m = np.argwhere(bad)[0]
        raise MotionFormatError(
            f"{path}: frame {t + 1}, marker {labels[m]!r}: coordinates must be finite, found {xyz[t, m].tolist()}"
        )
    seen = valid.any(axis=0)
    if not seen.any():
        raise MotionFormatError(
            f"{path}: every marker is missing in every frame; expected at least one sample"
        )
    if not seen.all():
        dropped = [labels[m] for m in np.flatnonzero(~seen)]
        warnings.warn(
            f"{path}: markers missing in all frames were dropped: {', '.join(dropped)}", stacklevel=2
        )
    keep = np.flatnonzero(seen)
    n_missing = int((~valid[:, keep]).sum())
    if n_missing:
        _log.info("%s: %d missing marker samples filled by linear interpolation", path, n_missing)
    pos = _fill_gaps(np.where(valid[..., None], xyz, 0.0)[:, keep], valid[:, keep]) * _UNITS_M[units.lower()]
    axis = _guess_up_axis(pos) if up_axis == "auto" else up_axis
    pos = to_z_up(pos, axis)
    names = _strip_prefix([labels[m] for m in keep])
    if len(set(names)) != len(names):
        names = [f"{n}#{i}" if names.count(n) > 1 else n for i, n in enumerate(names)]
    parents = (-1,) * len(names)
    try:
        skeleton = Skeleton(name=path.stem, joint_names=tuple(names), parents=parents)
    except ValueError:  # labels whose left/right swap is not an involution: no mirror map
        skeleton = Skeleton(path.stem, tuple(names), parents, mirror=tuple(range(len(names))))
    return Motion(
        positions=pos,
        fps_hz=rate,
        skeleton=skeleton,
        name=path.stem,
        provenance={
            "path": str(path),
            "format": "c3d",
            "units": units,
            "up_axis": axis,
            "missing_samples_filled": n_missing,
            "dropped_markers": [labels[m] for m in np.flatnonzero(~seen)],
        },
    )
