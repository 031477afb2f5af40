"""Dataset directories: stored samples by global index, and sequencing views over a split.

DatasetReader reads samples through the manifest; CaptureDataset is a map-style, numpy-only dataset of
sequencing views.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.capture.views import SEQUENCING, GroundTruth, Observations, make_view
from gttdata.manifest import Manifest, load_manifest
from gttdata.shards.reader import ShardReader

__all__ = ["CaptureDataset", "DatasetReader"]


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


class CaptureDataset:
    """Items are what a solver may see of one stored capture under a sequencing condition, plus its truth.

    Item ``i`` is sample ``i // n_variants`` in variant ``variants[i % n_variants]``. Under a list of
    sequencing conditions each item draws its condition, and under ``"none"`` its image permutation,
    from ``SeedSequence([seed, epoch, i])``: deterministic, and different per epoch after
    :meth:`set_epoch`. Shard handles are opened lazily in the process that reads (DataLoader workers
    included); nothing here imports torch.

    Example (not run as a doctest: needs torch and a generated dataset)::

        import torch

        ds = CaptureDataset("data/gttdata/tiny", split="train", sequencing=["none", "partial"], variant="all")
        # N differs per sample: one sample per step (batch_size=None) or a custom collate_fn.
        loader = torch.utils.data.DataLoader(ds, batch_size=None, shuffle=True, num_workers=2)
        for epoch in range(2):
            ds.set_epoch(epoch)  # workers are re-created each epoch (persistent_workers=False)
            for item in loader:
                x2d, X = item["obs"]["keypoints_px"], item["gt"]["points3d"]  # (N, J, 2), (N, J, 3)

    Args:
        root: Dataset directory (with ``manifest.json``).
        split: Split name.
        sequencing: ``"none"``, ``"partial"``, ``"full"``, or a list of them (mixed, drawn per item).
        variant: ``"orig"``, ``"all"`` (every stored variant), or a list of variant names.
        seed: Seed of the per-item draws.

    Raises:
        ValueError: Unknown sequencing or variant (the message lists the valid ones).
        ManifestError: No manifest or unknown split.
    """

    def __init__(
        self,
        root: str | Path,
        *,
        split: str = "train",
        sequencing: str | Sequence[str] = "none",
        variant: str | Sequence[str] = "orig",
        seed: int = 0,
    ) -> None:
        self.reader = DatasetReader(root, split)
        seqs = (sequencing,) if isinstance(sequencing, str) else tuple(sequencing)
        bad = [s for s in seqs if s not in SEQUENCING]
        if not seqs or bad:
            raise ValueError(
                f"sequencing must be one of {SEQUENCING} or a non-empty list of them, got {sequencing!r}"
            )
        stored = self.reader.variants
        if variant == "all":
            variants = stored
        else:
            variants = (variant,) if isinstance(variant, str) else tuple(variant)
        bad = [v for v in variants if v not in stored]
        if not variants or bad:
            raise ValueError(f"variant must be 'all' or among the stored variants {stored}, got {variant!r}")
        self.root, self.split, self.seed = Path(root), split, int(seed)
        self.sequencing: tuple[str, ...] = seqs
        self.variants: tuple[str, ...] = variants
        self.epoch = 0

    def __len__(self) -> int:
        return len(self.reader) * len(self.variants)

    def set_epoch(self, epoch: int) -> None:
        """Change the per-item draws (mixed sequencing, image permutation under ``none``)."""
        self.epoch = int(epoch)

    def _locate(self, i: int) -> tuple[int, str]:
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"{self.root}: item {i} out of range for {n} items (split {self.split!r})")
        i = int(i) % n
        return i // len(self.variants), self.variants[i % len(self.variants)]

    def _draw(self, i: int) -> tuple[str, int]:
        """The item's sequencing condition and permutation seed."""
        rng = np.random.default_rng(
            np.random.SeedSequence([self.seed, self.epoch, int(i) % max(len(self), 1)])
        )
        seq = (
            self.sequencing[int(rng.integers(len(self.sequencing)))]
            if len(self.sequencing) > 1
            else self.sequencing[0]
        )
        return seq, int(rng.integers(2**62))

    def sample(self, i: int) -> CaptureSample:
        """The stored capture behind item ``i`` (its variant), in true time order."""
        index, variant = self._locate(i)
        return self.reader.read_sample(index, variant)

    def view(self, i: int) -> tuple[Observations, GroundTruth]:
        """Item ``i`` as ``(Observations, GroundTruth)`` (see :func:`gttdata.capture.views.make_view`)."""
        sequencing, perm_seed = self._draw(i)
        return make_view(self.sample(i), sequencing, seed=perm_seed)

    def __getitem__(self, i: int) -> dict:
        """Item ``i`` as plain numpy arrays.

        Returns:
            ``{"name", "variant", "index", "sequencing", "obs": {...}, "gt": {...}}`` where ``obs`` holds
            ``sequencing``, ``cam_id`` (N,), ``K`` (N, 3, 3), ``cam_from_world`` (N, 4, 4),
            ``keypoints_px`` (N, J, 2) NaN where missing, ``visible`` (N, J), ``image_size`` (V, 2),
            ``skeleton`` (JSON string), and ``stream_index`` (N,) / ``timestamp_s`` (N,) only when the
            condition grants them; ``gt`` holds ``points3d`` (N, J, 3) metres, ``global_order`` (N,),
            ``affinity_nbr`` (N, 2) and ``affinity_w`` (N, 2) in view order, ``timestamp_s`` (N,) and
            ``perm`` (N,) (stored index of each view image). Never feed ``gt`` to a solver.
        """
        sample = self.sample(i)
        sequencing, perm_seed = self._draw(i)
        obs, gt = make_view(sample, sequencing, seed=perm_seed)
        o = {
            "sequencing": obs.sequencing,
            "cam_id": obs.cam_id,
            "K": obs.K,
            "cam_from_world": obs.cam_from_world,
            "keypoints_px": obs.keypoints_px,
            "visible": obs.visible,
            "image_size": obs.image_size,
            "skeleton": json.dumps(obs.skeleton.to_dict(), sort_keys=True),
        }
        if obs.stream_index is not None:
            o["stream_index"] = obs.stream_index
        if obs.timestamp_s is not None:
            o["timestamp_s"] = obs.timestamp_s
        g = {
            "points3d": gt.points3d,
            "global_order": gt.global_order,
            "affinity_nbr": gt.affinity_nbr,
            "affinity_w": gt.affinity_w,
            "timestamp_s": gt.timestamp_s,
            "perm": gt.perm,
        }
        return {
            "name": sample.name,
            "variant": sample.variant,
            "index": int(i),
            "sequencing": sequencing,
            "obs": o,
            "gt": g,
        }
