"""Per-camera clocks: the model ``t = offset_c + (1 + drift_c 1e-6) tau`` and its application to observations."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import cast

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError, SequencingError

__all__ = ["Clocks", "apply_clocks", "clock_times", "local_times", "per_camera_rates"]

#: Version of the clocks file layout written by :meth:`Clocks.save`.
CLOCKS_FORMAT = "gtt-clocks/1"


def per_camera_rates(
    cam_id: np.ndarray, fps: float | Sequence[float] | Mapping[int, float] | None
) -> dict[int, float]:
    """Nominal frame rate of every camera in ``cam_id``, Hz.

    Args:
        cam_id: Camera of each image, shape ``(N,)``.
        fps: One rate for all cameras, a sequence indexed by camera id, or a mapping camera id -> rate.
            None means 30 Hz for every camera (only relative timing matters to the solvers then; the
            reported offsets are in units of that nominal rate).

    Returns:
        ``{camera id: rate in Hz}`` for every camera present.

    Raises:
        GttNetError: A camera has no rate or a rate is not positive and finite.
    """
    cams = [int(c) for c in np.unique(np.asarray(cam_id))]
    if fps is None:
        rates = dict.fromkeys(cams, 30.0)
    elif isinstance(fps, Mapping):
        missing = [c for c in cams if c not in fps]
        if missing:
            raise GttNetError(f"fps: no frame rate for camera {missing[0]} (rates given for {sorted(fps)})")
        rates = {c: float(fps[c]) for c in cams}
    elif np.ndim(fps) == 0:
        rates = dict.fromkeys(cams, float(cast(float, fps)))
    else:
        seq = [float(x) for x in cast(Sequence[float], fps)]
        if cams and cams[-1] >= len(seq):
            raise GttNetError(f"fps: {len(seq)} rates given, expected one per camera id 0..{cams[-1]}")
        rates = {c: seq[c] for c in cams}
    bad = {c: r for c, r in rates.items() if not (np.isfinite(r) and r > 0)}
    if bad:
        c = next(iter(bad))
        raise GttNetError(f"fps: camera {c} rate must be a positive number of Hz, got {bad[c]}")
    return rates


def local_times(
    obs: Observations,
    rates: Mapping[int, float],
    frame_times_s: np.ndarray | None = None,
) -> np.ndarray:
    """Each image's time on its own camera's clock, seconds, shape ``(N,)``.

    ``frame_times_s[n]`` when given (e.g. the presentation timestamps ffprobe reports, which show dropped
    frames as gaps), else the observations' own ``stream_time_s`` when they carry it, else
    ``stream_index[n] / rate[cam_id[n]]`` (a stream index that skips is a dropped frame).

    Raises:
        SequencingError: Neither ``stream_index`` nor ``frame_times_s`` is available.
        GttNetError: ``frame_times_s`` has the wrong shape, is not finite, or disagrees with the stream order.
    """
    cam = np.asarray(obs.cam_id)
    if frame_times_s is None:
        frame_times_s = getattr(obs, "stream_time_s", None)
    if frame_times_s is not None:
        tau = np.asarray(frame_times_s, dtype=np.float64)
        if tau.shape != cam.shape:
            raise GttNetError(f"frame_times_s: expected shape ({cam.shape[0]},), got {tau.shape}")
        if not np.all(np.isfinite(tau)):
            raise GttNetError("frame_times_s: expected finite seconds, found NaN or inf")
        if obs.stream_index is not None:
            for c in np.unique(cam):
                sel = np.flatnonzero(cam == c)
                o = sel[np.argsort(obs.stream_index[sel], kind="stable")]
                if np.any(np.diff(tau[o]) <= 0):
                    raise GttNetError(
                        f"frame_times_s: camera {int(c)} times must increase with stream_index, they do not"
                    )
        return tau
    if obs.stream_index is None:
        raise SequencingError(
            "clock recovery needs each camera's frame order (sequencing 'partial' or 'full') or frame times; "
            f"input has sequencing {obs.sequencing!r}"
        )
    rate = np.array([rates[int(c)] for c in cam], dtype=np.float64)
    return np.asarray(obs.stream_index, dtype=np.float64) / rate


@dataclass(frozen=True)
class Clocks:
    """Recovered clock of every camera.

    Recovered clock of every camera: frame ``k`` of camera ``c`` was taken at global time
    ``offset_s[c] + (1 + drift_ppm[c] 1e-6) tau_k``, with ``tau_k`` the frame's time on the camera's own
    clock (``k / rate_hz[c]``, or the per-frame timestamp when one was given).

    Global time 0 is the first image of the earliest camera; drift is reported with zero mean over the
    cameras (absolute rate is not observable from the images, only rates relative to each other).

    Args:
        cameras: Camera ids, shape ``(V,)`` int, ascending.
        offset_s: Global time of each camera's local time 0, seconds, shape ``(V,)``.
        rate_hz: Nominal frame rate used for the local times, Hz, shape ``(V,)``.
        drift_ppm: Clock rate error relative to the cameras' mean, parts per million, shape ``(V,)``.
        offset_std_s: One-sigma uncertainty of each offset relative to the mean of all offsets, seconds,
            shape ``(V,)``.
        info: Diagnostics (front end, pair estimates, residuals), JSON-serialisable.
    """

    cameras: np.ndarray
    offset_s: np.ndarray
    rate_hz: np.ndarray
    drift_ppm: np.ndarray
    offset_std_s: np.ndarray
    info: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        cams = np.asarray(self.cameras, dtype=np.int64)
        object.__setattr__(self, "cameras", cams)
        for name in ("offset_s", "rate_hz", "drift_ppm", "offset_std_s"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.shape != cams.shape:
                raise ValueError(f"Clocks.{name} must have shape {cams.shape}, got {a.shape}")
            object.__setattr__(self, name, a)

    @property
    def n_cameras(self) -> int:
        """Number of cameras V."""
        return int(self.cameras.shape[0])

    def index(self, cam_id: np.ndarray) -> np.ndarray:
        """Row of each camera id in this table, shape like ``cam_id``.

        Raises:
            GttNetError: A camera id has no clock.
        """
        cam = np.asarray(cam_id, dtype=np.int64)
        pos = np.searchsorted(self.cameras, cam)
        ok = (pos < self.n_cameras) & (self.cameras[np.minimum(pos, self.n_cameras - 1)] == cam)
        if not np.all(ok):
            raise GttNetError(
                f"clocks: no clock for camera {int(cam[~ok][0])} (cameras {self.cameras.tolist()})"
            )
        return pos

    def times(self, cam_id: np.ndarray, tau_s: np.ndarray) -> np.ndarray:
        """Global times of frames with local times ``tau_s`` of cameras ``cam_id``, seconds."""
        i = self.index(cam_id)
        return self.offset_s[i] + (1.0 + 1e-6 * self.drift_ppm[i]) * np.asarray(tau_s, dtype=np.float64)

    def to_dict(self) -> dict:
        """JSON form: one entry per camera (offset, rate, drift, uncertainty) plus diagnostics."""
        return {
            "format": CLOCKS_FORMAT,
            "time_origin": "first image of the earliest camera",
            "cameras": [
                {
                    "camera": int(c),
                    "offset_s": float(o),
                    "rate_hz": float(r),
                    "drift_ppm": float(d),
                    "offset_std_s": float(s),
                }
                for c, o, r, d, s in zip(
                    self.cameras, self.offset_s, self.rate_hz, self.drift_ppm, self.offset_std_s, strict=True
                )
            ],
            "info": self.info,
        }

    @classmethod
    def from_dict(cls, d: Mapping, *, source: str = "clocks") -> Clocks:
        """Inverse of :meth:`to_dict`.

        Raises:
            GttNetError: A field is missing or has the wrong type (the message names ``source`` and field).
        """
        if d.get("format") != CLOCKS_FORMAT:
            raise GttNetError(
                f"{source}: field 'format': expected {CLOCKS_FORMAT!r}, got {d.get('format')!r}"
            )
        rows = d.get("cameras")
        if not isinstance(rows, list) or not rows:
            raise GttNetError(
                f"{source}: field 'cameras': expected a non-empty list, got {type(rows).__name__}"
            )
        cols: dict[str, list] = {
            k: [] for k in ("camera", "offset_s", "rate_hz", "drift_ppm", "offset_std_s")
        }
        for i, row in enumerate(rows):
            for k in cols:
                v = row.get(k) if isinstance(row, Mapping) else None
                if not isinstance(v, int | float) or isinstance(v, bool):
                    raise GttNetError(f"{source}: field 'cameras[{i}].{k}': expected a number, got {v!r}")
                cols[k].append(v)
        order = np.argsort(cols["camera"], kind="stable")
        return cls(
            cameras=np.asarray(cols["camera"], dtype=np.int64)[order],
            offset_s=np.asarray(cols["offset_s"])[order],
            rate_hz=np.asarray(cols["rate_hz"])[order],
            drift_ppm=np.asarray(cols["drift_ppm"])[order],
            offset_std_s=np.asarray(cols["offset_std_s"])[order],
            info=dict(d.get("info") or {}),
        )

    def save(self, path: str | Path, *, overwrite: bool = False) -> Path:
        """Write the clocks as JSON atomically (temp file in the same directory, then rename).

        Raises:
            FileExistsError: ``path`` exists and ``overwrite`` is False.
        """
        path = Path(path)
        if path.exists() and not overwrite:
            raise FileExistsError(f"{path} exists; pass overwrite=True (--overwrite) to replace it")
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(self.to_dict(), f, indent=2)
                f.write("\n")
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path

    @classmethod
    def load(cls, path: str | Path) -> Clocks:
        """Read a file written by :meth:`save`."""
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise GttNetError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
        if not isinstance(d, Mapping):
            raise GttNetError(f"{path}: expected a JSON object, got {type(d).__name__}")
        return cls.from_dict(d, source=str(path))


def clock_times(obs: Observations, clocks: Clocks, *, frame_times_s: np.ndarray | None = None) -> np.ndarray:
    """Global capture time of every image of ``obs`` under ``clocks``, seconds, shape ``(N,)``, input order."""
    rates = {int(c): float(r) for c, r in zip(clocks.cameras, clocks.rate_hz, strict=True)}
    tau = local_times(obs, rates, frame_times_s)
    return clocks.times(obs.cam_id, tau)


def apply_clocks(
    obs: Observations, clocks: Clocks, *, frame_times_s: np.ndarray | None = None
) -> Observations:
    """Observations with ``sequencing="full"``: timestamps from ``clocks``, images sorted by them.

    Args:
        obs: Observations with each camera's frame order (``partial`` or ``full``; the timestamps of a
            ``full`` input are replaced), or with ``frame_times_s``.
        clocks: Recovered clocks.
        frame_times_s: Per-image local times, shape ``(N,)`` (see :func:`local_times`).

    Returns:
        The same images in recovered time order (``argsort`` of :func:`clock_times`, stable).
    """
    t = clock_times(obs, clocks, frame_times_s=frame_times_s)
    seq = np.argsort(t, kind="stable")
    si = obs.stream_index
    if si is None:  # frame times only: rank within each stream
        si = np.empty(obs.n_images, dtype=np.int64)
        for c in np.unique(obs.cam_id):
            sel = np.flatnonzero(obs.cam_id == c)
            si[sel[np.argsort(t[sel], kind="stable")]] = np.arange(sel.size)
    return replace(obs.take(seq), sequencing="full", stream_index=np.asarray(si)[seq], timestamp_s=t[seq])
