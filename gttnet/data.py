"""The only bridge from gttdata samples to GTT-Net training items (torch Dataset, sampler and collate)."""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from gttdata.capture.views import GroundTruth, Observations, make_view
from gttnet.errors import GttNetError
from gttnet.model.inputs import SequenceInput, prepare_inputs, prepare_stream_ordered_inputs

__all__ = [
    "TrainItem",
    "RecipeSource",
    "ShardSource",
    "SequenceDataset",
    "EpochStream",
    "collate_items",
    "affinity_targets",
    "prepare_item",
    "open_source",
    "ConcatSource",
    "check_registered",
    "save_item",
    "load_item",
    "ITEM_FORMAT",
]

#: Format tag of a cached item file (plain tensors and strings, read with ``weights_only=True``).
ITEM_FORMAT = "gttnet-item/1"

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainItem:
    """One training sequence: network inputs plus the supervision the losses may use.

    Args:
        inputs: Observation-only network input.
        points3d: Ground-truth joints in world, metres, shape ``(N, J, 3)``.
        target_binary: Binary A^G over each image's neighbourhood, shape ``(N, K)``.
        target_continuous: Continuous A^G (interpolation weights) over the neighbourhood, shape ``(N, K)``.
        name: Sample name and condition, for logs.
        condition: The capture's sequencing condition (``inputs.sequencing`` differs when an order-free
            capture is presented with estimated camera streams).
    """

    inputs: SequenceInput
    points3d: torch.Tensor
    target_binary: torch.Tensor
    target_continuous: torch.Tensor
    name: str
    condition: str = ""

    def to(self, device: torch.device | str, dtype: torch.dtype | None = None) -> TrainItem:
        """Move every tensor to ``device`` (floating ones cast to ``dtype``)."""
        return replace(
            self,
            inputs=self.inputs.to(device, dtype),
            points3d=self.points3d.to(device=device, dtype=dtype),
            target_binary=self.target_binary.to(device=device, dtype=dtype),
            target_continuous=self.target_continuous.to(device=device, dtype=dtype),
        )

    def rotated(self, R: torch.Tensor) -> TrainItem:
        """Structure, cameras and ground truth rotated together about the world origin (F^GR)."""
        R = R.to(self.points3d)
        return replace(self, inputs=self.inputs.rotated(R), points3d=self.points3d @ R.T)


def _item_to_plain(item: TrainItem) -> dict:
    plain: dict = {"format": ITEM_FORMAT}
    plain["inputs"] = {f.name: getattr(item.inputs, f.name) for f in fields(item.inputs)}
    plain.update({f.name: getattr(item, f.name) for f in fields(item) if f.name != "inputs"})
    return plain


def _item_from_plain(plain: object) -> TrainItem:
    """Rebuild a :class:`TrainItem`; every field must have the type its dataclass declares."""
    if not isinstance(plain, dict) or plain.get("format") != ITEM_FORMAT:
        found = plain.get("format") if isinstance(plain, dict) else type(plain).__name__
        raise ValueError(f"format: expected {ITEM_FORMAT!r}, found {found!r}")
    raw_inputs = plain.get("inputs")
    if not isinstance(raw_inputs, dict):
        raise ValueError(f"inputs: expected a mapping, found {type(raw_inputs).__name__}")

    def typed(owner, values: dict) -> dict:
        out = {}
        for f in fields(owner):
            if f.name == "inputs":
                continue
            v = values.get(f.name)
            if f.name in _ITEM_STR_FIELDS:
                ok, want = isinstance(v, str), "a string"
            else:
                ok = isinstance(v, torch.Tensor) or (f.name == "chain" and v is None)
                want = "a tensor"
            if not ok:
                raise ValueError(f"{f.name}: expected {want}, found {type(v).__name__}")
            out[f.name] = v
        return out

    return TrainItem(
        inputs=SequenceInput(**typed(SequenceInput, raw_inputs)),
        **typed(TrainItem, plain),
    )


_ITEM_STR_FIELDS = ("sequencing", "domain", "name", "condition")


def save_item(item: TrainItem, path: str | Path) -> Path:
    """Write a training item as plain tensors and strings (no pickled classes), atomically.

    Raises:
        OutputError: One line naming the path when the write fails (full disk, read-only...).
    """
    import io

    from gttdata.fileio import atomic_write

    buf = io.BytesIO()
    torch.save(_item_to_plain(item), buf)
    with atomic_write(path, "wb") as fh:
        fh.write(buf.getbuffer())
    return Path(path)


def load_item(path: str | Path) -> TrainItem:
    """Read a file written by :func:`save_item` with ``torch.load(weights_only=True)``: never code.

    Raises:
        ValueError: The file is not a cached item in this layout (one line naming the file and why).
    """
    import pickle

    try:
        plain = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        first = str(exc).splitlines()[0] if str(exc) else exc.__class__.__name__
        raise ValueError(f"{path}: not weights only, refused unread ({first[:120]})") from None
    except Exception as exc:  # noqa: BLE001 - torch raises EOFError, RuntimeError... on damaged files
        raise ValueError(f"{path}: unreadable ({exc.__class__.__name__})") from exc
    try:
        return _item_from_plain(plain)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from exc


def affinity_targets(gt_nbr: np.ndarray, gt_w: np.ndarray, nbr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A^G gathered over each image's neighbourhood.

    Args:
        gt_nbr: True previous/next image of another camera, shape ``(N, 2)``, ``-1`` where none.
        gt_w: Their interpolation weights, shape ``(N, 2)``.
        nbr: Neighbourhoods, shape ``(N, K)``, ``-1`` padded.

    Returns:
        ``(binary, continuous)``, each shape ``(N, K)``: binary is symmetric temporal adjacency (m is
        n's neighbour in time or n is m's); continuous is row n's interpolation weight of m.
    """
    n = nbr.shape[0]
    valid = nbr >= 0
    m = np.where(valid, nbr, 0)
    fwd = gt_nbr[:, None, :] == m[:, :, None]  # (N, K, 2): m is one of n's temporal neighbours
    back = (gt_nbr[m] == np.arange(n)[:, None, None]).any(-1)  # n is one of m's
    binary = (fwd.any(-1) | back) & valid
    cont = np.where(fwd & valid[..., None], gt_w[:, None, :], 0.0).sum(-1)
    return binary.astype(np.float64), cont


def prepare_item(
    obs: Observations, gt: GroundTruth, *, k: int, name: str = "", stream_order: bool = False
) -> TrainItem:
    """Network inputs (from ``obs`` only) and supervision (from ``gt``) for one view of a capture.

    Args:
        obs: Observations of one sequencing condition.
        gt: The matching ground truth.
        k: Neighbours per image K.
        name: Label for logs.
        stream_order: An order-free ``obs`` gets the inputs inference gives it with ``stream_order`` on
            (:func:`gttnet.model.inputs.prepare_stream_ordered_inputs`, estimated camera streams); other
            conditions are unaffected.

    Returns:
        A :class:`TrainItem` on the CPU (float32).
    """
    if stream_order and obs.sequencing == "none":
        from gttnet.model.inference import STREAM_ORDER_K

        inputs = prepare_stream_ordered_inputs(obs, k=k, order_k=STREAM_ORDER_K)
    else:
        inputs = prepare_inputs(obs, k=k)
    binary, cont = affinity_targets(gt.affinity_nbr, gt.affinity_w, inputs.nbr.numpy())
    return TrainItem(
        inputs=inputs,
        points3d=torch.as_tensor(gt.points3d, dtype=torch.float32),
        target_binary=torch.as_tensor(binary, dtype=torch.float32),
        target_continuous=torch.as_tensor(cont, dtype=torch.float32),
        name=f"{name}:{obs.sequencing}",
        condition=obs.sequencing,
    )


class RecipeSource:
    """Samples of one split built on the fly from a gttdata generate recipe (deterministic per index).

    Args:
        recipe: A gttdata GenerateRecipe.
        split: Split name.
    """

    def __init__(self, recipe, split: str) -> None:
        from gttdata.generate_plan import n_samples, validate_inputs

        validate_inputs(recipe)  # a missing motion file fails here, in one line, not inside a worker
        counts = n_samples(recipe)
        if split not in counts:
            raise ValueError(f"the data recipe has no split {split!r}; splits: {sorted(counts)}")
        self.recipe, self.split, self._n = recipe, split, counts[split]

    def __len__(self) -> int:
        return self._n

    def view(self, index: int, sequencing: str, variant: str) -> tuple[Observations, GroundTruth]:
        """Observations and ground truth of sample ``index`` under ``sequencing``, variant ``variant``."""
        from gttdata.generate_plan import build_sample

        samples = {s.variant: s for s in build_sample(self.recipe, self.split, index)}
        if variant not in samples:
            raise ValueError(f"sample {index} has no variant {variant!r}; variants: {sorted(samples)}")
        return make_view(samples[variant], sequencing)


class ShardSource:
    """Samples of one split read from gttdata shards (``gttdata.dataset.CaptureDataset``), opened lazily.

    Args:
        root: Dataset directory.
        split: Split name.
    """

    def __init__(self, root: str | Path, split: str) -> None:
        self.root, self.split = str(root), split
        self._sets: dict[tuple[str, str], object] = {}
        self._n = len(self._dataset("none", "orig"))

    def _dataset(self, sequencing: str, variant: str):
        key = (sequencing, variant)
        if key not in self._sets:
            from gttdata.dataset import CaptureDataset

            self._sets[key] = CaptureDataset(
                self.root, split=self.split, sequencing=sequencing, variant=variant
            )
        return self._sets[key]

    def __len__(self) -> int:
        return self._n

    def view(self, index: int, sequencing: str, variant: str) -> tuple[Observations, GroundTruth]:
        """Observations and ground truth of sample ``index`` under ``sequencing``, variant ``variant``."""
        return self._dataset(sequencing, variant).view(index)

    def __getstate__(self) -> dict:
        # h5py handles must be opened in each worker, never pickled.
        return {**self.__dict__, "_sets": {}}


class ViewSource(Protocol):
    """What :class:`ConcatSource` needs of a source: the view of one of its samples."""

    def view(self, index: int, sequencing: str, variant: str) -> tuple[Observations, GroundTruth]:
        """The view of local sample ``index`` under ``sequencing`` for ``variant``."""
        ...


class ConcatSource:
    """Several sources seen as one, index after index.

    Args:
        sources: ``(source, count)`` pairs; the first ``count`` samples of each are used.
    """

    def __init__(self, sources: Sequence[tuple[ViewSource, int]]) -> None:
        self.parts = [(src, int(n)) for src, n in sources if n > 0]
        self._starts = np.cumsum([0] + [n for _, n in self.parts])

    def __len__(self) -> int:
        return int(self._starts[-1])

    def view(self, index: int, sequencing: str, variant: str) -> tuple[Observations, GroundTruth]:
        """The view of global sample ``index`` (see :meth:`RecipeSource.view`)."""
        part = int(np.searchsorted(self._starts, index, side="right") - 1)
        src, _ = self.parts[part]
        return src.view(index - int(self._starts[part]), sequencing, variant)


def _open_one(spec, split: str):
    from gttdata.recipe import load_recipe

    gen = load_recipe(spec.generate, spec.overrides)
    if spec.kind == "recipe":
        return RecipeSource(gen, split)
    root = Path(spec.root or gen.output_dir)
    if not any(root.glob("**/*.h5")):
        from gttdata.generation import generate_dataset

        log.info("no shards under %s: generating them from %s", root, spec.generate)
        if spec.root:
            gen = load_recipe(spec.generate, [*spec.overrides, f"output_dir={root}"])
        generate_dataset(gen, resume=True, progress=False)  # keeps what a killed run wrote
    if spec.manifest is not None:
        check_registered(root, spec.manifest)
    return ShardSource(root, split)


_VERIFIED: set[tuple[str, str]] = set()


def check_registered(root: str | Path, manifest: str | Path) -> None:
    """Check that the shards under ``root`` are the dataset a registered manifest describes.

    Args:
        root: Dataset directory (with its own ``manifest.json``).
        manifest: The registered manifest (e.g. ``manifests/default.json``).

    Raises:
        ValueError: One line naming the manifest and the first difference (recipe hash, or a shard's
            presence, size or SHA-256).
    """
    from gttdata.manifest import load_manifest, verify_manifest

    key = (str(Path(root).resolve()), Path(manifest).read_text() if Path(manifest).is_file() else "")
    if key in _VERIFIED:  # the train and validation splits open the same shards: check them once
        return
    registered = load_manifest(manifest)
    local = load_manifest(root)
    if local.recipe_hash != registered.recipe_hash:
        raise ValueError(
            f"{root}: recipe_hash {local.recipe_hash} differs from {manifest} ({registered.recipe_hash}); "
            "regenerate the shards with the registered recipe"
        )
    problems = verify_manifest(root, registered)
    if problems:
        more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
        raise ValueError(f"{root} does not match {manifest}: {problems[0]}{more}")
    _VERIFIED.add(key)
    log.info("shards under %s match %s", root, manifest)


def open_source(data_spec, split: str, *, limit: str = "max_train") -> ConcatSource:
    """The samples of ``split`` over every source of a :class:`~gttnet.train.recipe.DataSpec`.

    Args:
        data_spec: The recipe's data section.
        split: Split name.
        limit: Which per-source cap applies: ``"max_train"`` or ``"max_val"``.

    Returns:
        A :class:`ConcatSource`.
    """
    parts = []
    for spec in data_spec.sources:
        src = _open_one(spec, split)
        cap = getattr(spec, limit)
        parts.append((src, len(src) if cap is None else min(cap, len(src))))
    return ConcatSource(parts)


class SequenceDataset(torch.utils.data.Dataset):
    """Map-style dataset of :class:`TrainItem`; keys are ``(index, salt, sequencing | None)``.

    The sequencing condition and variant of a key with ``sequencing=None`` are drawn from
    ``SeedSequence([seed, index, salt])``, so the stream of items depends only on the keys, never on
    worker count or process (which makes resumption and DDP exact).

    Args:
        source: A :class:`RecipeSource` or :class:`ShardSource`.
        k: Neighbours per image K.
        sequencing: Weight of each condition.
        variants: Variants to draw from.
        seed: Seed of the draws.
        cache: ``"memory"`` (per process), ``"disk"`` (``.pt`` files under ``cache_dir``, shared by every
            DataLoader worker and kept for resumption) or ``"none"``.
        cache_dir: Directory of the disk cache.
        indices: Sample indices to use (default: all).
        stream_order: Order-free items get estimated camera streams (:func:`prepare_item`).
    """

    def __init__(
        self,
        source,
        *,
        k: int,
        sequencing: dict[str, float],
        variants: Sequence[str] = ("orig",),
        seed: int = 0,
        cache: str = "memory",
        cache_dir: str | Path | None = None,
        indices: Sequence[int] | None = None,
        stream_order: bool = False,
    ) -> None:
        if cache not in ("memory", "disk", "none"):
            raise ValueError(f"cache must be 'memory', 'disk' or 'none', got {cache!r}")
        if cache == "disk" and cache_dir is None:
            raise ValueError("cache 'disk' needs a cache_dir")
        self.source, self.k, self.seed, self.cache = source, k, seed, cache
        self.stream_order = stream_order
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        names = [s for s, w in sequencing.items() if w > 0]
        w = np.array([sequencing[s] for s in names], dtype=np.float64)
        self.conditions, self.weights = names, w / w.sum()
        self.variants = list(variants)
        self.indices = list(range(len(source))) if indices is None else list(indices)
        self._cache: dict[tuple[int, str, str], TrainItem] = {}
        self._unusable: dict[tuple[int, str, str], GttNetError] = {}  # views no solver can use, and why
        self._disk_full = False
        self._refused = 0

    def _write_cache(self, item: TrainItem, path: Path) -> None:
        """Cache ``item`` at ``path``; a failed write (full disk) warns once and stops disk caching.

        The write is atomic (:func:`gttdata.fileio.atomic_write`): workers and ranks may race on the same
        item, and a failed write leaves neither a partial item nor a temporary file behind.
        """
        from gttdata.errors import OutputError

        try:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                from gttdata.fileio import write_error

                raise write_error(path.parent, exc) from exc
            save_item(item, path)
        except OutputError as exc:
            self._disk_full = True
            log.warning("%s; training goes on without the disk cache of items", exc)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, key: tuple[int, int, str | None]) -> TrainItem:
        """The item at ``key = (position, salt, sequencing or None)``.

        A capture no solver can use (no joint seen by two cameras: far, occluded or two-camera recipes make
        a few) is skipped for the next position, as a data loader skips a bad file; it is warned about once
        and never prepared again.

        Raises:
            GttNetError: No capture of the dataset is usable.
        """
        pos, salt, sequencing = key
        last: GttNetError | None = None
        for step in range(len(self)):
            try:
                return self._item((pos + step) % len(self), salt, sequencing)
            except GttNetError as exc:
                last = exc
        raise GttNetError(f"none of the {len(self)} captures can be used for training; the last: {last}")

    def _item(self, pos: int, salt: int, sequencing: str | None) -> TrainItem:
        index = self.indices[pos]
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, index, salt]))
        if sequencing is None:
            sequencing = self.conditions[int(rng.choice(len(self.conditions), p=self.weights))]
        variant = self.variants[int(rng.integers(len(self.variants)))]
        ck = (index, sequencing, variant)
        if ck in self._cache:
            return self._cache[ck]
        if ck in self._unusable:
            raise self._unusable[ck]
        path = None
        if self.cache == "disk":
            assert self.cache_dir is not None  # checked in __init__
            streams = "-streams" if self.stream_order and sequencing == "none" else ""
            path = self.cache_dir / f"{index:06d}-{sequencing}{streams}-{variant}-k{self.k}.pt"
            if path.is_file():
                try:
                    return load_item(path)  # weights only: a planted file never runs code
                except ValueError as exc:  # a damaged or foreign cache entry is rebuilt, never trusted
                    self._refused += 1
                    if self._refused == 1:  # a cache of an older gttnet would repeat it for every item
                        log.warning("%s; rebuilding it (and any other such item, silently)", exc)
                    else:
                        log.debug("%s; rebuilding it", exc)
        obs, gt = self.source.view(index, sequencing, variant)
        try:
            item = prepare_item(obs, gt, k=self.k, name=f"{index}/{variant}", stream_order=self.stream_order)
        except GttNetError as exc:
            self._unusable[ck] = exc
            log.warning("capture %d (%s) skipped: %s", index, sequencing, exc)
            raise
        if path is not None and not self._disk_full:
            self._write_cache(item, path)
        elif self.cache == "memory":
            self._cache[ck] = item
        return item


class EpochStream(torch.utils.data.Sampler):
    """Endless stream of keys: epoch e is a seeded permutation, strided over DDP ranks.

    Args:
        n: Dataset length.
        seed: Seed of the permutations.
        rank: This process's rank.
        world: Number of processes.
        start_epoch: Epoch to start in (resumption).
        start_pos: Keys of ``start_epoch`` to skip (resumption).
    """

    def __init__(
        self, n: int, *, seed: int, rank: int = 0, world: int = 1, start_epoch: int = 0, start_pos: int = 0
    ):
        if n < world:
            raise ValueError(f"{n} training samples cannot be split over {world} processes")
        self.n, self.seed, self.rank, self.world = n, seed, rank, world
        self.start_epoch, self.start_pos = start_epoch, start_pos

    def epoch_keys(self, epoch: int) -> list[tuple[int, int, None]]:
        """This rank's keys of one epoch (equal count on every rank)."""
        perm = np.random.default_rng(np.random.SeedSequence([self.seed, 7919, epoch])).permutation(self.n)
        per_rank = self.n // self.world
        mine = perm[self.rank :: self.world][:per_rank]
        return [(int(i), epoch, None) for i in mine]

    def __iter__(self) -> Iterator[tuple[int, int, None]]:
        epoch, pos = self.start_epoch, self.start_pos
        while True:
            yield from self.epoch_keys(epoch)[pos:]
            epoch, pos = epoch + 1, 0


def collate_items(items: list[TrainItem]) -> list[TrainItem]:
    """Keep a batch as a list: sequences differ in N."""
    return list(items)
