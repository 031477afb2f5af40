"""Dataset plots with matplotlib (Agg): timestamp raster, noise and missing-rate histograms, lengths, motion sources."""

from __future__ import annotations

import logging
import sys
from collections import Counter
from pathlib import Path
from typing import Protocol

import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.preview._gl import require

__all__ = ["SampleSource", "collect_statistics", "open_source", "plot_dataset", "plot_timestamp_raster"]

_log = logging.getLogger(__name__)
_DPI = 100


class SampleSource(Protocol):
    """Anything indexable that reads samples: a ShardReader or DatasetReader."""

    def __len__(self) -> int: ...

    def read_sample(self, i: int, variant: str = "orig") -> CaptureSample:
        """Sample ``i`` as the named variant (``"orig"`` or an augmented copy)."""
        ...


def _figure(width_in: float, height_in: float):
    """A pyplot-free Figure (no global state, rendered by Agg when saved)."""
    require("matplotlib")
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), dpi=_DPI, layout="constrained")


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, format="png")
    return path


def _raster(ax, sample: CaptureSample, *, lw: float, labels: bool) -> None:
    """Draw one raster panel on ``ax``: ticks per camera row and the global-order line."""
    V = sample.n_cameras
    t_ms = sample.timestamp_s * 1000.0
    order = np.argsort(t_ms, kind="stable")
    ax.plot(t_ms[order], sample.cam_id[order], color="0.75", lw=0.6, zorder=1)
    names = []
    for v in range(V):
        t = np.sort(t_ms[sample.cam_id == v])
        ax.vlines(t, v - 0.35, v + 0.35, color=f"C{v % 10}", lw=lw, zorder=2)
        rate = 1000.0 / float(np.median(np.diff(t))) if len(t) > 1 else float("nan")
        names.append(f"cam {v}: {rate:.1f} Hz, first {t[0]:.1f} ms" if len(t) else f"cam {v}: no images")
    ax.set_yticks(range(V), names if labels else [f"cam {v}" for v in range(V)])
    ax.set_ylim(V - 0.5, -0.5)
    ax.grid(axis="x", color="0.9", lw=0.5)


def plot_timestamp_raster(sample: CaptureSample, path: str | Path, *, zoom_above: int = 60) -> Path:
    """Raster of capture times: one row per camera, one tick per image, a grey line through global time order.

    Row labels give each camera's measured rate (median interval) and its first-image offset, so the
    stagger and unequal rates are visible at a glance. Dense captures get a second panel zoomed on
    the first six periods of the slowest camera, where the individual ticks stay apart.

    Args:
        sample: The capture.
        path: Output PNG.
        zoom_above: Add the zoomed panel when the sample has more images than this.

    Returns:
        ``path``.
    """
    V = sample.n_cameras
    zoom = sample.n_images > zoom_above
    fig = _figure(8.0, (1.3 + 0.45 * V) * (1.8 if zoom else 1.0))
    ax = fig.add_subplot(2 if zoom else 1, 1, 1)
    _raster(ax, sample, lw=0.6 if zoom else 1.6, labels=True)
    ax.set_xlabel("capture time [ms]")
    ax.set_title(
        f"{sample.name}: {sample.n_images} images from {V} unsynchronized cameras "
        f"(min cross-camera gap {_min_gap_ms(sample):.1f} ms)",
        fontsize=9,
    )
    if zoom:
        periods = [np.median(np.diff(np.sort(sample.timestamp_s[sample.cam_id == v]))) for v in range(V)]
        periods = [p for p in periods if np.isfinite(p)] or [0.1]
        t0 = float(sample.timestamp_s.min()) * 1000.0
        ax2 = fig.add_subplot(2, 1, 2)
        _raster(ax2, sample, lw=1.6, labels=False)
        ax2.set_xlim(t0 - 2.0, t0 + 6000.0 * max(periods))
        ax2.set_xlabel("capture time [ms], first six periods of the slowest camera")
    return _save(fig, path)


def _min_gap_ms(sample: CaptureSample) -> float:
    t = sample.timestamp_s[np.argsort(sample.timestamp_s, kind="stable")]
    c = sample.cam_id[np.argsort(sample.timestamp_s, kind="stable")]
    d = np.diff(t)[c[1:] != c[:-1]]
    return float(d.min() * 1000.0) if len(d) else float("nan")


def open_source(path: str | Path, split: str | None = None) -> SampleSource:
    """A reader for a dataset directory (through its manifest) or a single shard file.

    Args:
        path: Dataset directory holding ``manifest.json``, or a ``shard-XXXXX.h5`` file.
        split: Split of a dataset directory (None: every split in manifest order); ignored for a shard.

    Raises:
        ManifestError, ShardFormatError: Not a readable dataset or shard.
    """
    from gttdata.dataset import DatasetReader
    from gttdata.shards.reader import ShardReader

    path = Path(path)
    if path.is_dir():
        return DatasetReader(path, split)
    if not path.exists():
        raise FileNotFoundError(2, "No such file or directory", str(path))
    return ShardReader(path)


def _motion_labels(sample: CaptureSample) -> list[str]:
    """Motion kind of each subject/event: ``procedural/<kind>`` or the motion file's name."""
    names = [m.get("name", "") for m in sample.meta.get("motions", [])] or [sample.motion_name]
    return ["/".join(n.split("/")[:2]) if n.startswith("procedural/") else n for n in names]


def collect_statistics(source: SampleSource, *, max_samples: int = 1000, progress: bool = False) -> dict:
    """Per-sample statistics from the samples' ``meta`` and arrays.

    Args:
        source: Samples to read.
        max_samples: Read at most this many, evenly spaced over the source.
        progress: tqdm bar on stderr.

    Returns:
        ``sigma_px`` (per camera or per sample, px), ``missing_rate``, ``n_images``, ``duration_s``
        (1-D float arrays) and ``motions`` (Counter of motion labels), plus ``n_read``.
    """
    from tqdm import tqdm

    n = len(source)
    idx = np.unique(np.linspace(0, n - 1, min(n, max_samples)).round().astype(int)) if n else np.zeros(0, int)
    sigma: list[float] = []
    missing: list[float] = []
    n_images: list[int] = []
    duration: list[float] = []
    motions: Counter[str] = Counter()
    for i in tqdm(idx, desc="statistics", unit="sample", disable=not progress, file=sys.stderr):
        s = source.read_sample(int(i))
        sigma.extend(np.ravel(s.meta.get("capture", {}).get("sigma_px", [])).astype(float).tolist())
        missing.append(float(s.meta.get("missing_rate", 1.0 - s.visible.mean())))
        n_images.append(s.n_images)
        duration.append(float(np.ptp(s.timestamp_s)) if s.n_images else 0.0)
        motions.update(_motion_labels(s))
    arr = {
        k: np.asarray(v, dtype=np.float64)
        for k, v in (
            ("sigma_px", sigma),
            ("missing_rate", missing),
            ("n_images", n_images),
            ("duration_s", duration),
        )
    }
    return {**arr, "motions": motions, "n_read": len(idx)}


def _hist(values: np.ndarray, path: Path, *, xlabel: str, title: str) -> Path:
    fig = _figure(5.0, 3.2)
    ax = fig.add_subplot()
    if len(values):
        ax.hist(values, bins=min(30, max(5, len(np.unique(values)))), color="C0", edgecolor="white", lw=0.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("count")
    ax.set_title(title, fontsize=9)
    return _save(fig, path)


def _lengths(stats: dict, path: Path, title: str) -> Path:
    fig = _figure(8.0, 3.2)
    for k, (key, label) in enumerate(
        (("n_images", "images per sample N"), ("duration_s", "capture span [s]"))
    ):
        ax = fig.add_subplot(1, 2, k + 1)
        if len(stats[key]):
            ax.hist(
                stats[key],
                bins=min(30, max(5, len(np.unique(stats[key])))),
                color=f"C{k + 1}",
                edgecolor="white",
            )
        ax.set_xlabel(label)
        ax.set_ylabel("samples")
    fig.suptitle(f"{title}: sequence lengths", fontsize=9)
    return _save(fig, path)


def _sources(motions: Counter, path: Path, title: str, top: int = 25) -> Path:
    items = motions.most_common(top)
    rest = sum(motions.values()) - sum(c for _, c in items)
    if rest:
        items.append((f"{len(motions) - top} others", rest))
    fig = _figure(7.0, 1.2 + 0.25 * max(len(items), 1))
    ax = fig.add_subplot()
    ax.barh(range(len(items)), [c for _, c in items], color="C4")
    ax.set_yticks(range(len(items)), [k for k, _ in items], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("subject-captures")
    ax.set_title(f"{title}: motion sources", fontsize=9)
    return _save(fig, path)


def plot_dataset(
    source: SampleSource | str | Path,
    out_dir: str | Path,
    *,
    split: str | None = None,
    sample: int = 0,
    max_samples: int = 1000,
    progress: bool = False,
    title: str | None = None,
) -> list[Path]:
    """Write the dataset plots into a folder.

    Write the dataset plots: ``timestamp_raster.png`` (of sample ``sample``), ``noise_sigma.png``,
    ``missing_rate.png``, ``sequence_length.png`` and ``motion_sources.png``.

    Args:
        source: A reader, or a dataset directory / shard path (see :func:`open_source`).
        out_dir: Output directory (created).
        split: Split when ``source`` is a dataset directory (None: all).
        sample: Index of the sample whose timestamps are plotted.
        max_samples: Statistics from at most this many samples, evenly spaced.
        progress: tqdm bar on stderr while reading.
        title: Name shown in the plot titles (default: the path's name, or ``"dataset"``).

    Returns:
        The written paths.

    Raises:
        PreviewDependencyError: matplotlib is not installed.
    """
    require("matplotlib")
    reader = open_source(source, split) if isinstance(source, str | Path) else source
    out = Path(out_dir)
    if title is None:
        title = Path(source).name if isinstance(source, str | Path) else "dataset"
        title += f" [{split}]" if split else ""
    stats = collect_statistics(reader, max_samples=max_samples, progress=progress)
    sub = f"{title} ({stats['n_read']} samples)"
    _log.info("dataset plots of %s into %s", sub, out)
    return [
        plot_timestamp_raster(reader.read_sample(sample), out / "timestamp_raster.png"),
        _hist(stats["sigma_px"], out / "noise_sigma.png", xlabel="detection noise sigma [px]", title=sub),
        _hist(
            stats["missing_rate"], out / "missing_rate.png", xlabel="fraction of joints missing", title=sub
        ),
        _lengths(stats, out / "sequence_length.png", sub),
        _sources(stats["motions"], out / "motion_sources.png", sub),
    ]
