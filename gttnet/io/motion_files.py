"""Standard motion files out: a reconstruction in time order as TRC, C3D or CSV (and the existing .h5/.npz).

A :class:`MotionTable` holds the rows of a reconstruction sorted in time, with each row's time, the
camera that took it and its frame number in that camera's video. :func:`motion_table` builds it from
a reconstruction and the view it was computed on:

* with timestamps (``full`` sequencing, a shared clock) rows are sorted by time;
* with clocks recovered by a method (``Reconstruction.info["timestamp_s"]``) by the recovered times;
* otherwise by the recovered order (``Reconstruction.order``), turned so that each camera's frames
  run forward (the order is only known up to reversal); the times are then the rank divided by the
  summed camera rate (or rank × 1 s without rates) and ``timed`` is False.

Writers pick the layout from the suffix (:func:`write_motion`): ``.trc`` (OpenSim / Pose2Sim marker
trajectories), ``.c3d`` (through the ``c3d`` package; metres, camera of each row in the points'
camera mask, times and cameras in the ``GTT`` parameter group), ``.csv`` (one row per image:
``time_s, camera, frame, <joint>_x, <joint>_y, <joint>_z ...``). :func:`resample` interpolates a
timed table onto a uniform rate.
"""

from __future__ import annotations

import csv
import io
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gttdata.fileio import write_bytes_atomic

__all__ = [
    "MOTION_SUFFIXES",
    "MotionTable",
    "motion_table",
    "read_c3d_points",
    "read_motion_csv",
    "read_trc",
    "resample",
    "write_motion",
]

#: Suffixes :func:`write_motion` writes.
MOTION_SUFFIXES: tuple[str, ...] = (".trc", ".c3d", ".csv")


@dataclass(frozen=True)
class MotionTable:
    """Reconstructed joints in time order.

    Args:
        points3d: Joints in world, metres, shape ``(M, J, 3)``; NaN where not reconstructed.
        time_s: Time of each row, seconds, shape ``(M,)``, non-decreasing.
        camera: Camera name of each row (``""`` for resampled rows), length M.
        frame: Frame number of each row in its camera's video, shape ``(M,)`` (-1 for resampled rows).
        row: Row of the reconstruction (view image index) of each table row, shape ``(M,)`` (-1 resampled).
        joint_names: J names.
        timed: Whether ``time_s`` are times (False: ranks scaled by a nominal rate).
        rate_hz: Mean number of rows per second.
    """

    points3d: np.ndarray
    time_s: np.ndarray
    camera: tuple[str, ...]
    frame: np.ndarray
    row: np.ndarray
    joint_names: tuple[str, ...]
    timed: bool
    rate_hz: float

    @property
    def n_rows(self) -> int:
        """Number of rows M."""
        return int(self.time_s.shape[0])


def _orient(order_rank: np.ndarray, cam_id: np.ndarray, stream: np.ndarray | None) -> np.ndarray:
    """Flip a recovered rank so that each camera's frames mostly run forward."""
    if stream is None:
        return order_rank
    score = 0.0
    for v in np.unique(cam_id):
        rows = np.flatnonzero(cam_id == v)
        if rows.size > 1:
            s = np.argsort(stream[rows], kind="stable")
            score += float(np.sum(np.sign(np.diff(order_rank[rows][s]))))
    return order_rank if score >= 0 else order_rank.max() - order_rank


def motion_table(rec, view) -> MotionTable:
    """Rows of ``rec`` in time order (see the module docstring).

    Args:
        rec: A :class:`~gttnet.methods.Reconstruction` of ``view.observations``.
        view: The :class:`~gttdata.recording.RecordingView` (camera names, frames, rates) it ran on.
    """
    obs = view.observations
    n = obs.n_images
    recovered = rec.info.get("timestamp_s") if isinstance(rec.info, dict) else None
    if obs.timestamp_s is not None:
        t, timed = np.asarray(obs.timestamp_s, dtype=np.float64), True
    elif recovered is not None and np.shape(recovered) == (n,):
        t, timed = np.asarray(recovered, dtype=np.float64), True
    else:
        rank = np.arange(n) if rec.order is None else np.asarray(rec.order)
        rank = _orient(rank.astype(np.float64), obs.cam_id, obs.stream_index)
        fps = np.asarray(view.fps, dtype=np.float64)
        rate = float(np.nansum(fps)) if np.any(np.isfinite(fps)) else 1.0
        t, timed = rank / rate, False
    order = np.argsort(t, kind="stable")
    ts = t[order]
    span = float(ts[-1] - ts[0]) if n > 1 else 0.0
    return MotionTable(
        points3d=np.asarray(rec.points3d, dtype=np.float64)[order],
        time_s=ts,
        camera=tuple(view.camera_names[c] for c in obs.cam_id[order]),
        frame=np.asarray(view.frame)[order].astype(np.int64),
        row=order.astype(np.int64),
        joint_names=tuple(obs.skeleton.joint_names),
        timed=timed,
        rate_hz=(n - 1) / span if span > 0 else 1.0,
    )


def resample(table: MotionTable, rate_hz: float) -> MotionTable:
    """Linear interpolation of each joint onto a uniform grid ``t0 + k / rate_hz`` within the table's span.

    A joint is NaN at a grid time unless reconstructed on both sides of it.

    Raises:
        ValueError: For an untimed table (no clock: uniform resampling would invent times) or a bad rate.
    """
    if not table.timed:
        raise ValueError(
            "resampling needs times: give timestamps on a shared clock or use a method that recovers clocks"
        )
    if not rate_hz > 0:
        raise ValueError(f"resample rate must be > 0 Hz, got {rate_hz}")
    t0, t1 = float(table.time_s[0]), float(table.time_s[-1])
    grid = t0 + np.arange(int(np.floor((t1 - t0) * rate_hz + 1e-9)) + 1) / rate_hz
    j = table.points3d.shape[1]
    out = np.full((grid.shape[0], j, 3), np.nan)
    for p in range(j):
        ok = np.all(np.isfinite(table.points3d[:, p]), axis=1)
        if ok.sum() < 2:
            continue
        tt = table.time_s[ok]
        inside = (grid >= tt[0]) & (grid <= tt[-1])
        for a in range(3):
            out[inside, p, a] = np.interp(grid[inside], tt, table.points3d[ok, p, a])
    m = grid.shape[0]
    return MotionTable(
        points3d=out,
        time_s=grid,
        camera=("",) * m,
        frame=np.full(m, -1, dtype=np.int64),
        row=np.full(m, -1, dtype=np.int64),
        joint_names=table.joint_names,
        timed=True,
        rate_hz=float(rate_hz),
    )


def _num(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.9f}"


def _atomic(path: Path, data: bytes) -> None:
    write_bytes_atomic(path, data)  # fsync + rename; a full disk is one line, no .tmp left


def _trc_bytes(table: MotionTable, name: str) -> bytes:
    j = len(table.joint_names)
    rate = f"{table.rate_hz:.6g}"
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate}\t{rate}\t{table.n_rows}\t{j}\tm\t{rate}\t1\t{table.n_rows}",
        "Frame#\tTime\t" + "\t\t\t".join(table.joint_names) + "\t\t",
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, j + 1)),
        "",
    ]
    for k in range(table.n_rows):
        vals = "\t".join(_num(v) for v in table.points3d[k].ravel())
        lines.append(f"{k + 1}\t{table.time_s[k]:.9f}\t{vals}")
    return ("\n".join(lines) + "\n").encode()


def read_trc(path: str | Path) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, str]:
    """Read a TRC file: ``(marker names, time_s (M,), points (M, J, 3), units)``; blanks are NaN."""
    lines = Path(path).read_text().splitlines()
    keys, values = lines[1].split("\t"), lines[2].split("\t")
    meta = dict(zip(keys, values, strict=False))
    names = tuple(n for n in lines[3].split("\t")[2:] if n)
    j = len(names)
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    t = np.array([float(r[1]) for r in rows])
    pts = np.full((len(rows), j, 3), np.nan)
    for k, r in enumerate(rows):
        vals = r[2 : 2 + 3 * j] + [""] * (3 * j - len(r[2 : 2 + 3 * j]))
        pts[k] = np.array([float(v) if v.strip() else np.nan for v in vals]).reshape(j, 3)
    return names, t, pts, meta.get("Units", "m")


def _csv_bytes(table: MotionTable) -> bytes:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["time_s", "camera", "frame"] + [f"{n}_{a}" for n in table.joint_names for a in "xyz"])
    for k in range(table.n_rows):
        w.writerow(
            [f"{table.time_s[k]:.9f}", table.camera[k], int(table.frame[k])]
            + [_num(v) for v in table.points3d[k].ravel()]
        )
    return buf.getvalue().encode()


def read_motion_csv(
    path: str | Path,
) -> tuple[tuple[str, ...], np.ndarray, list[str], np.ndarray, np.ndarray]:
    """Read a CSV written by :func:`write_motion`: ``(joint names, time_s, cameras, frames, points (M, J, 3))``."""
    rows = list(csv.reader(io.StringIO(Path(path).read_text())))
    head = rows[0]
    names = tuple(h[:-2] for h in head[3::3])
    body = rows[1:]
    t = np.array([float(r[0]) for r in body])
    pts = np.array([[float(v) if v else np.nan for v in r[3:]] for r in body]).reshape(
        len(body), len(names), 3
    )
    return names, t, [r[1] for r in body], np.array([int(r[2]) for r in body]), pts


def _param_array(values: np.ndarray, width: int = 250) -> np.ndarray:
    """A 1-D parameter as a (rows, width) array: C3D dimensions are at most 255."""
    m = values.shape[0]
    rows = max(1, -(-m // width))
    out = np.full(rows * width, np.nan if values.dtype.kind == "f" else -1, dtype=values.dtype)
    out[:m] = values
    return out.reshape(rows, width)


def _c3d_bytes(table: MotionTable) -> bytes:
    import c3d

    cams = sorted({c for c in table.camera if c})
    w = c3d.Writer(point_rate=float(table.rate_hz), point_units="m   ")
    w.set_point_labels([n[:30] for n in table.joint_names])
    g = w.add_group(20, "GTT", "gtt: time and camera of each frame")
    if table.n_rows * 4 <= 30000:  # a C3D parameter holds at most 32 KB
        g.add_array("TIME_S", "time of each frame, s", _param_array(table.time_s.astype(np.float32)))
        idx = np.array([cams.index(c) if c else -1 for c in table.camera], dtype=np.int16)
        g.add_array("CAMERA", "camera index of each frame (-1: resampled)", _param_array(idx))
    names, width = c3d.Writer.pack_labels(cams or ["-"])
    g.add_str("CAMERAS", "camera names, in index order", names, width, len(cams or ["-"]))
    g.add_array("TIMED", "1: times are clock times; 0: ranks", np.array([int(table.timed)], dtype=np.int16))
    frames = []
    for k in range(table.n_rows):
        pts = np.zeros((len(table.joint_names), 5), dtype=np.float32)
        X = table.points3d[k]
        ok = np.all(np.isfinite(X), axis=1)
        pts[ok, :3] = X[ok]
        pts[~ok, 3] = -1.0  # C3D: a negative residual marks an invalid point
        if table.camera[k]:
            pts[ok, 4] = float(1 << cams.index(table.camera[k]))  # camera mask: who saw it
        frames.append((pts, np.zeros((0, 0), dtype=np.float32)))
    w.add_frames(frames)
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w.write(buf)
    return buf.getvalue()


def read_c3d_points(path: str | Path) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, str]:
    """Read a C3D file: ``(labels, time_s (M,), points (M, J, 3), units)``, invalid points NaN.

    Times come from the ``GTT:TIME_S`` parameter when present, else ``frame / rate``.
    """
    import c3d

    with open(path, "rb") as h, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = c3d.Reader(h)
        labels = tuple(str(s).strip() for s in r.point_labels)
        units = r.get("POINT:UNITS").string_value.strip()
        frames = []
        for _, p, _ in r.read_frames():
            X = p[:, :3].astype(np.float64)
            X[p[:, 3] < 0] = np.nan
            frames.append(X)
        pts = np.stack(frames)
        param = r.get("GTT:TIME_S")
        if param is not None:
            t = np.asarray(param.float_array, dtype=np.float64).ravel()
            t = t[np.isfinite(t)][: pts.shape[0]]
        else:
            t = np.arange(pts.shape[0]) / float(r.point_rate)
    return labels, t, pts, units


def write_motion(table: MotionTable, path: str | Path) -> Path:
    """Write ``table`` as ``.trc``, ``.c3d`` or ``.csv`` by suffix (temporary file, then rename)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".trc":
        data = _trc_bytes(table, path.name)
    elif suffix == ".c3d":
        data = _c3d_bytes(table)
    elif suffix == ".csv":
        data = _csv_bytes(table)
    else:
        raise ValueError(
            f"{path}: motion file suffix must be one of {', '.join(MOTION_SUFFIXES)}, got {suffix!r}"
        )
    _atomic(path, data)
    return path
