"""DatasetReader: random access by global index to the samples of a dataset directory, through its manifest."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.manifest import Manifest, load_manifest
from gttdata.shards.reader import ShardReader

__all__ = ["DatasetReader"]


class DatasetReader:
    """The samples of one split (or all splits, in manifest order) as one indexable sequence.

    Shard files are opened lazily, one handle per shard and per process; the reader is picklable.

    Args:
        root: Dataset directory holding ``manifest.json``.
        split: Split name, or None for every split one after the other.
        manifest: An already loaded manifest (default: read ``root/manifest.json``).

    Raises:
        ManifestError: No manifest, or unknown split (the message lists the splits).
    """

    def __init__(
        self, root: str | Path, split: str | None = None, *, manifest: Manifest | None = None
    ) -> None:
        self.root = Path(root)
        self.manifest = manifest or load_manifest(self.root)
        self.split = split
        entries = self.manifest.shards_of(split)
        self.shards = [ShardReader(self.root / e.path) for e in entries]
        self._entries = entries
        self._starts = np.cumsum([0] + [e.n_samples for e in entries])

    def __len__(self) -> int:
        return int(self._starts[-1])

    def locate(self, i: int) -> tuple[ShardReader, int]:
        """The shard holding global sample ``i`` and the sample's local index in it."""
        n = len(self)
        if not -n <= i < n:
            raise IndexError(
                f"{self.root}: sample index {i} out of range for {n} samples (split {self.split})"
            )
        i = int(i) % n
        k = int(np.searchsorted(self._starts, i, side="right") - 1)
        return self.shards[k], i - int(self._starts[k])

    @property
    def variants(self) -> tuple[str, ...]:
        """Variant names every sample holds, ``"orig"`` first."""
        return self.manifest.variants

    def read_sample(self, i: int, variant: str = "orig") -> CaptureSample:
        """Read global sample ``i`` (see :meth:`ShardReader.read_sample`)."""
        shard, local = self.locate(i)
        return shard.read_sample(local, variant)

    def close(self) -> None:
        """Close every open shard handle of this process."""
        for s in self.shards:
            s.close()
