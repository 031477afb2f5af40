"""Reconstruction inputs and outputs: importers of shard, DLOE .mat and GTT-Net JSON files, and writers.

``load_input(path, fmt=..., sequencing=...)`` reads any supported file into the solver inputs of one
sequencing condition (``Observations``) plus the ground truth when the file holds it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.capture.views import GroundTruth, Observations, make_view, view_permutation
from gttnet.errors import ImportFormatError
from gttnet.io._views import UNITS, ImportedCapture

__all__ = ["FORMATS", "UNITS", "LoadedInput", "detect_format", "load_input"]

log = logging.getLogger(__name__)

#: Input formats and the file suffixes that select them under ``fmt="auto"``.
FORMATS: dict[str, tuple[str, ...]] = {
    "h5": (".h5", ".hdf5"),
    "dloe-mat": (".mat",),
    "gttnet-json": (".json",),
}


@dataclass(frozen=True)
class LoadedInput:
    """A reconstruction input in one sequencing view.

    Args:
        observations: Solver inputs (what a method may see).
        ground_truth: Ground truth in the same image order, or None when the file holds none.
        image_index: Stored (file) index of each view image, shape ``(N,)``.
        source: File path.
        fmt: Format name (a key of :data:`FORMATS`).
        units: Length unit the file was read in (converted to metres).
    """

    observations: Observations
    ground_truth: GroundTruth | None
    image_index: np.ndarray
    source: str
    fmt: str
    units: str


def detect_format(path: str | Path) -> str:
    """Format name from a file suffix (a directory is a dataset of ``h5`` shards).

    Raises:
        ImportFormatError: For an unknown suffix.
    """
    if Path(path).is_dir():
        return "h5"  # a dataset directory of shards
    suffix = Path(path).suffix.lower()
    for name, suffixes in FORMATS.items():
        if suffix in suffixes:
            return name
    known = ", ".join(s for v in FORMATS.values() for s in v)
    raise ImportFormatError(
        f"{path}: cannot tell the format from suffix {suffix!r}; expected one of {known} or --format"
    )


def _read_foreign(path: Path, fmt: str, units: str | None) -> ImportedCapture:
    if fmt == "dloe-mat":
        from gttnet.io.dloe_mat import read_dloe_mat

        return read_dloe_mat(path, units=units)
    from gttnet.io.gttnet_json import read_gttnet_json

    return read_gttnet_json(path, units=units)


def load_input(
    path: str | Path,
    *,
    fmt: str = "auto",
    sequencing: str | None = None,
    sample: int = 0,
    variant: str = "orig",
    units: str | None = None,
    seed: int | None = None,
    split: str | None = None,
) -> LoadedInput:
    """Read a reconstruction input file into one sequencing view.

    Args:
        path: Input file, or a dataset directory of shards (``manifest.json``).
        fmt: ``"auto"`` (by suffix) or a key of :data:`FORMATS`.
        sequencing: ``"none"``, ``"partial"`` or ``"full"``; None: the richest the file supports
            (``full`` for shards and files with a global order, else ``partial``).
        sample: Sample index inside a shard file, or inside ``split`` of a dataset directory (h5 only).
        variant: Input variant inside a shard (h5 only).
        units: Length unit of a foreign file (key of :data:`UNITS`); None: the unit the file records
            (our GTT-Net JSON files do), else metres with a ``UserWarning`` saying so (the authors' files
            record none; theirs are in inches). Shards are always metres.
        seed: Seed of the random image permutation under ``none``.
        split: Split of a dataset directory (None: the sample index runs over all splits in manifest
            order); a shard file holds one split and ignores it.

    Returns:
        The loaded input.

    Raises:
        ImportFormatError: For a malformed file or an unknown suffix.
        SequencingError: For ``full`` on a file without a global order.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(2, "No such file", str(path))
    fmt = detect_format(path) if fmt == "auto" else fmt
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r}; expected auto or one of {', '.join(FORMATS)}")
    if units is not None and units not in UNITS:
        raise ValueError(f"unknown units {units!r}; expected one of {', '.join(UNITS)}")
    cap: CaptureSample | ImportedCapture
    if fmt == "h5":
        if units not in (None, "m"):
            raise ValueError(f"{path}: shards are stored in metres; --units {units} does not apply")
        units = "m"
        from gttnet.io.shards import read_shard_sample

        if path.is_dir() and split is not None:
            from gttdata.dataset import DatasetReader

            reader = DatasetReader(path, split)
            if not 0 <= sample < len(reader):
                raise ValueError(
                    f"{path}: split {split!r} holds samples 0-{len(reader) - 1}, got --sample {sample}"
                )
            cap = reader.read_sample(sample, variant)
        else:
            cap = read_shard_sample(path, sample=sample, variant=variant)
        sequencing = sequencing or "full"
    else:
        cap = _read_foreign(path, fmt, units)
        units = cap.file_units
        sequencing = sequencing or cap.best_sequencing
    obs, gt = make_view(cap, sequencing, seed=seed)
    index = view_permutation(cap, sequencing, seed)
    log.info("%s (%s): %d images, sequencing %s", path, fmt, obs.n_images, obs.sequencing)
    return LoadedInput(obs, gt, np.asarray(index, dtype=np.int64), str(path), fmt, units)
