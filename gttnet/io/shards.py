"""Importer of gtt's own HDF5 shards (one file or a dataset directory): any sample and input variant."""

from __future__ import annotations

from pathlib import Path

from gttdata.capture.sample import CaptureSample
from gttnet.errors import ImportFormatError

__all__ = ["read_shard_sample"]


def read_shard_sample(path: str | Path, *, sample: int = 0, variant: str = "orig") -> CaptureSample:
    """Read one capture from a shard file or a dataset directory.

    A file is read with ``gttdata.shards.reader.ShardReader`` (``sample`` = index inside the file); a
    directory holding ``manifest.json`` with ``gttdata.dataset.DatasetReader`` over all its
    splits in manifest order (``sample`` = global index).

    Args:
        path: A ``shard-XXXXX.h5`` file or a dataset directory.
        sample: Index of the sample inside the shard, or in the dataset.
        variant: Input variant (``"orig"`` or an augmentation name stored in the shard).

    Returns:
        The stored :class:`~gttdata.capture.sample.CaptureSample` (metres, true time order).

    Raises:
        ImportFormatError: If the reader is unavailable, the sample index or variant does not exist.
    """
    try:
        from gttdata.dataset import DatasetReader
        from gttdata.shards.reader import ShardReader
    except ModuleNotFoundError as exc:
        raise ImportFormatError(
            f"{path}: cannot read shards: gttdata.shards is not available ({exc})"
        ) from exc
    reader = DatasetReader(path) if Path(path).is_dir() else ShardReader(path)
    try:
        return reader.read_sample(sample, variant)
    except (IndexError, KeyError) as exc:
        raise ImportFormatError(
            f"{path}: sample {sample}, variant {variant!r}: expected a stored sample and variant, found none ({exc})"
        ) from exc
    finally:
        close = getattr(reader, "close", None)
        if callable(close):
            close()
