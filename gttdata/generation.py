"""generate_dataset: turn a recipe into a directory of deterministic HDF5 shards and a manifest, in parallel, resumably."""

from __future__ import annotations

import concurrent.futures as cf
import json
import logging
import multiprocessing as mp
import os
import queue as queue_mod
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from gttdata import __version__
from gttdata.errors import ManifestError, RecipeError, ShardFormatError
from gttdata.fileio import OutputLock, check_output, die_with_parent, refuse_foreign_output, remove_output
from gttdata.generate_plan import build_sample, n_samples, validate_inputs
from gttdata.manifest import (
    MANIFEST_NAME,
    Manifest,
    build_manifest,
    load_manifest,
    verify_manifest,
    write_manifest,
)
from gttdata.recipe import GenerateRecipe, recipe_hash, recipe_to_dict
from gttdata.shards.inventory import file_sha256, scan_shards
from gttdata.shards.reader import ShardReader
from gttdata.shards.schema import SCHEMA_VERSION, SHARD_SUFFIX, TMP_SUFFIX, shard_file_name
from gttdata.shards.writer import ShardWriter

__all__ = ["BlockPlan", "generate_dataset", "parse_shard_range", "plan_blocks", "storage_attrs"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class BlockPlan:
    """One unit of work: block ``shard_index`` of ``split`` holds samples ``[first_index, first_index + n_samples)``.

    Args:
        split: Split name.
        shard_index: Block index k within the split.
        first_index: ``k * samples_per_shard``.
        n_samples: Samples in the block (the last block of a split may be short).
    """

    split: str
    shard_index: int
    first_index: int
    n_samples: int


def plan_blocks(recipe: GenerateRecipe) -> list[BlockPlan]:
    """Every block of the dataset: splits in recipe order, then block index (the ``--shard-range`` index)."""
    size = recipe.shard.samples_per_shard
    out = []
    for split, n in n_samples(recipe).items():
        for k in range((n + size - 1) // size):
            out.append(BlockPlan(split, k, k * size, min(size, n - k * size)))
    return out


def parse_shard_range(text: str | tuple[int, int] | None, n_blocks: int) -> range:
    """Blocks selected by ``"a:b"`` (Python slice semantics, either end optional) or ``"a"`` (one block).

    Raises:
        RecipeError: Malformed text, naming the expected form and the number of blocks.
    """
    if text is None:
        return range(n_blocks)
    if isinstance(text, tuple):
        return range(n_blocks)[slice(*text)]
    a, sep, b = str(text).partition(":")
    try:
        lo = int(a) if a.strip() else None
        hi = int(b) if b.strip() else None
    except ValueError as exc:
        raise RecipeError(
            f"--shard-range: expected 'a:b' with integers (0 <= a < b <= {n_blocks}), found {text!r}"
        ) from exc
    if not sep:
        hi = None if lo is None else lo + 1
    chosen = range(n_blocks)[slice(lo, hi)]
    if n_blocks and not chosen:
        raise RecipeError(
            f"--shard-range: {text!r} selects none of the {n_blocks} blocks (0..{n_blocks - 1})"
        )
    return chosen


def storage_attrs(recipe: GenerateRecipe) -> dict:
    """Root attributes every shard of ``recipe`` carries: generator, recipe hash and canonical recipe JSON.

    ``output_dir`` is cleared first: where a dataset is written does not change its content, so the
    same recipe gives byte-identical shards in any directory.
    """
    stored = replace(recipe, output_dir="")
    return {
        "generator": f"gttdata {__version__}",
        "recipe_hash": recipe_hash(stored),
        "recipe": json.dumps(recipe_to_dict(stored), sort_keys=True, separators=(",", ":")),
    }


def _block_files(split_dir: Path, k: int) -> tuple[list[Path], list[Path]]:
    """Final and temporary files of block ``k`` (parts in order)."""
    stem = shard_file_name(k)[: -len(SHARD_SUFFIX)]
    finals = sorted(
        split_dir.glob(f"{stem}.p*{SHARD_SUFFIX}"), key=lambda p: int(p.name.split(".p")[1].split(".")[0])
    )
    first = split_dir / shard_file_name(k)
    finals = ([first] if first.exists() else []) + finals
    tmps = sorted(split_dir.glob(f"{stem}*{SHARD_SUFFIX}{TMP_SUFFIX}"))
    return finals, tmps


def _write_block(recipe: GenerateRecipe, plan: BlockPlan, out_dir: str, attrs: dict, progress=None) -> int:
    """Worker: build and write one block; returns the number of images written. Spawn-safe (module level)."""
    split_dir = Path(out_dir) / plan.split
    split_dir.mkdir(parents=True, exist_ok=True)
    finals, tmps = _block_files(split_dir, plan.shard_index)
    for p in finals + tmps:  # stale parts of an earlier run must not survive next to the new ones
        p.unlink()
    n_images = 0
    with ShardWriter(
        split_dir,
        split=plan.split,
        shard_index=plan.shard_index,
        first_index=plan.first_index,
        max_samples=plan.n_samples,
        max_bytes=recipe.shard.max_bytes,
        compression=recipe.shard.compression,
        attrs=attrs,
        parts=True,
        rename_on_close=False,
    ) as writer:
        for i in range(plan.first_index, plan.first_index + plan.n_samples):
            group = build_sample(recipe, plan.split, i)
            _check_usable(group[0], plan.split, i)
            writer.write(group)
            n_images += group[0].n_images
            if progress is not None:
                progress(group[0].n_images)
    return n_images


def _check_usable(sample, split: str, index: int) -> None:
    """Refuse a sample no solver can use: fewer than two cameras with images, or no joint seen twice.

    Generation stops with one line rather than writing a dataset of unusable samples (a one-frame
    motion, a window shorter than a frame, or drop rates that leave nothing).
    """
    n_cams = len(np.unique(sample.cam_id)) if sample.n_images else 0
    seen_twice = int((sample.visible.sum(axis=0) >= 2).sum()) if sample.n_images else 0
    if n_cams < 2 or seen_twice == 0:
        raise RecipeError(
            f"splits.{split} sample {index} ({sample.motion_name}): expected images from at least 2 cameras "
            f"with a joint seen in 2 or more, found {sample.n_images} images from {n_cams} cameras and "
            f"{seen_twice} such joints; lengthen the motion or capture.window_s, or lower the drop rates"
        )


def _block_ok(out_dir: Path, plan: BlockPlan, attrs: dict, known: dict[str, str]) -> str | None:
    """Why block ``plan`` on disk cannot be kept (None when it is complete and intact)."""
    finals, _ = _block_files(out_dir / plan.split, plan.shard_index)
    if not finals:
        return "missing"
    nxt = plan.first_index
    for part, path in enumerate(finals):
        rel = path.relative_to(out_dir).as_posix()
        if rel in known and file_sha256(path) != known[rel]:
            return f"{rel}: sha256 differs from the previous manifest"
        try:
            with ShardReader(path) as reader:
                a = reader.attrs
                if a.get("recipe_hash") != attrs["recipe_hash"]:
                    return f"{rel}: written by another recipe"
                if a.get("generator") != attrs["generator"]:
                    return f"{rel}: written by {a.get('generator')}, not {attrs['generator']}"
                if a.get("schema_version") != SCHEMA_VERSION:  # e.g. 1.1: no attribute checksum to verify
                    return f"{rel}: schema {a.get('schema_version')}, this gttdata writes {SCHEMA_VERSION}"
                if (a.get("part"), a.get("first_index"), a.get("split")) != (part, nxt, plan.split):
                    return f"{rel}: part {a.get('part')} first_index {a.get('first_index')} out of sequence"
                reader.check()
                nxt += len(reader)
        except ShardFormatError as exc:
            return str(exc)
    if nxt != plan.first_index + plan.n_samples:
        return f"holds {nxt - plan.first_index} of {plan.n_samples} samples"
    return None


def _check_foreign(out_dir: Path, attrs: dict) -> None:
    """Refuse to mix shards of two recipes in one directory."""
    for path in scan_shards(out_dir)[0]:
        try:
            with ShardReader(path) as reader:
                reader.check_attrs()  # a flipped byte in recipe_hash is damage, not another recipe
                found = reader.attrs.get("recipe_hash")
        except ShardFormatError:
            continue  # unreadable or damaged: its block is regenerated (resume) or overwritten
        if found != attrs["recipe_hash"]:
            raise ManifestError(
                f"{path}: recipe_hash: expected {attrs['recipe_hash'][:12]} (this recipe), found {str(found)[:12]}; "
                "write each recipe to its own output directory (--out), or pass --overwrite to replace the old dataset"
            )


_PROGRESS = None  # in a worker: the queue its progress goes to (set by _worker_init)


def _worker_init(q, parent: int) -> None:
    """Pool initializer: exit with the parent ``parent`` (even after ``kill -9``), report progress to ``q``."""
    global _PROGRESS
    from gttdata.threads import limit_worker_threads

    die_with_parent(parent)
    limit_worker_threads()  # one BLAS thread per worker unless --threads / GTT_THREADS says otherwise
    _PROGRESS = q


def _write_block_in_worker(recipe: GenerateRecipe, plan: BlockPlan, out_dir: str, attrs: dict) -> int:
    assert _PROGRESS is not None, "the pool initializer sets the progress queue"
    return _write_block(recipe, plan, out_dir, attrs, _PROGRESS.put)


def _run_blocks(recipe, todo: list[BlockPlan], out_dir: Path, attrs: dict, workers: int, bar) -> None:
    def tick(n_images: int) -> None:
        bar.update(1)
        bar.images += n_images

    if workers <= 1 or len(todo) <= 1:
        for plan in todo:
            _write_block(recipe, plan, str(out_dir), attrs, tick)
        return
    ctx = mp.get_context("spawn")  # h5py and forked HDF5 state do not mix; spawn works everywhere
    q = ctx.Queue()  # no Manager: a manager process would outlive a killed parent
    with cf.ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=_worker_init, initargs=(q, os.getpid())
    ) as pool:
        futures = [pool.submit(_write_block_in_worker, recipe, plan, str(out_dir), attrs) for plan in todo]
        pending = set(futures)
        try:
            while pending:
                done, pending = cf.wait(pending, timeout=0.2, return_when=cf.FIRST_EXCEPTION)
                _drain(q, tick)
                for f in done:
                    f.result()  # re-raise the first worker error here
        except BaseException:
            for f in pending:
                f.cancel()
            raise
        _drain(q, tick)


def _drain(q, tick) -> None:
    while True:
        try:
            tick(q.get_nowait())
        except queue_mod.Empty:
            return


class _Bar:
    """tqdm progress over samples with images/s in the postfix (a no-op without tqdm or when disabled)."""

    def __init__(self, total: int, enabled: bool, desc: str) -> None:
        self.images, self._bar = 0, None
        if enabled:
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit="sample", desc=desc, dynamic_ncols=True, smoothing=0.1)

    def update(self, n: int) -> None:
        if self._bar is not None:
            self._bar.update(n)
            rate = self._bar.format_dict.get("rate")
            if rate and self._bar.n:
                self._bar.set_postfix_str(f"{rate * self.images / self._bar.n:.0f} img/s", refresh=False)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def _previous_manifest(out_dir: Path) -> dict[str, str]:
    """SHA-256 per shard of an existing manifest (removed: the shards are about to change)."""
    path = out_dir / MANIFEST_NAME
    if not path.exists():
        return {}
    try:
        known = {e.path: e.sha256 for e in load_manifest(path).shards}
    except ManifestError:
        known = {}
    path.unlink(missing_ok=True)
    return known


def generate_dataset(
    recipe: GenerateRecipe,
    *,
    workers: int = 1,
    shard_range: str | tuple[int, int] | None = None,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    counts: dict[str, int] | None = None,
) -> Manifest | None:
    """Generate the shards of ``recipe`` into ``recipe.output_dir``, then write its manifest.

    Block k of split s holds samples ``[k*S, (k+1)*S)`` (S = ``shard.samples_per_shard``) and is written
    by one task; a block that would exceed ``shard.max_bytes`` continues in part files
    ``shard-0000k.p1.h5``... Rollover points depend only on the block's content, so the files are
    byte-identical for any ``workers`` and any ``shard_range`` split. Parts of a block are renamed from
    last to first after all were fsynced: ``shard-0000k.h5`` exists only when its block is complete.

    Args:
        recipe: A validated recipe.
        workers: Processes (spawn); 1 runs in this process.
        shard_range: Blocks to write, ``"a:b"`` over :func:`plan_blocks` (for array jobs); None: all.
        resume: Keep blocks already on disk that verify (recipe hash, sample coverage, every chunk's
            Fletcher-32 checksum re-read, SHA-256 against a previous manifest when there is one);
            regenerate the rest. A folder holding shards of another recipe is refused.
        overwrite: Delete the dataset files in range first (all shards and the manifest without
            ``shard_range``). Without ``resume`` or ``overwrite``, existing files in range are refused.
        progress: Show a tqdm progress bar (samples/s, images/s, ETA) on stderr.
        counts: When given, filled with ``samples_written`` and ``samples_kept`` (in range, kept by
            ``resume`` because they verified), so a report never calls verified samples generated.

    Returns:
        The written and verified manifest, or None when blocks outside ``shard_range`` are still
        missing (the job that completes the dataset writes it; so does ``gttdata manifest DIR``).

    Raises:
        RecipeError: Missing motion files or a bad ``shard_range``.
        ManifestError: The output directory holds shards of another recipe, or the written dataset
            does not verify.
        OutputError: Existing files without ``resume``/``overwrite``; another process writing the
            folder (a run over the whole dataset excludes all others; ``shard_range`` jobs may run
            together); an unwritable output or a full disk (temporary files are removed).
    """
    out_dir = Path(recipe.output_dir)
    validate_inputs(recipe)
    blocks = plan_blocks(recipe)
    selected = [blocks[i] for i in parse_shard_range(shard_range, len(blocks))]
    refuse_foreign_output(out_dir, writer="gttdata generate")  # before the lock file is made
    with OutputLock(out_dir, "gttdata generate", shared=shard_range is not None):
        return _generate_locked(
            recipe, out_dir, blocks, selected, workers, shard_range, resume, overwrite, progress, counts
        )


def _existing_files(out_dir: Path, selected: list[BlockPlan], whole: bool) -> list[Path]:
    """Dataset files a run over ``selected`` would replace (all shards and the manifest when ``whole``)."""
    if whole:
        shards, tmps = scan_shards(out_dir)
        manifest = [out_dir / MANIFEST_NAME] if (out_dir / MANIFEST_NAME).exists() else []
        return shards + tmps + manifest
    found = []
    for plan in selected:
        finals, tmps = _block_files(out_dir / plan.split, plan.shard_index)
        found += finals + tmps
    return found


def _generate_locked(
    recipe, out_dir, blocks, selected, workers, shard_range, resume, overwrite, progress, counts=None
):
    whole = len(selected) == len(blocks)
    existing = _existing_files(out_dir, selected, whole)
    check_output(out_dir, exists=bool(existing), resume=resume, overwrite=overwrite, what="a dataset")
    if overwrite:
        remove_output(existing)
    attrs = storage_attrs(recipe)
    _check_foreign(out_dir, attrs)  # --resume continues only a dataset of this very recipe
    known = _previous_manifest(out_dir)
    todo = []
    for plan in selected:
        why = _block_ok(out_dir, plan, attrs, known) if resume else "not resuming"
        if why is None:
            _log.info("%s block %d: verified, kept", plan.split, plan.shard_index)
        else:
            if resume:
                _log.info("%s block %d: regenerating (%s)", plan.split, plan.shard_index, why)
            todo.append(plan)
    _log.info(
        "%s: %d blocks in range, %d to write with %d workers", recipe.name, len(selected), len(todo), workers
    )
    n_todo = sum(p.n_samples for p in todo)
    if counts is not None:
        counts.update(samples_written=n_todo, samples_kept=sum(p.n_samples for p in selected) - n_todo)
    bar = _Bar(n_todo, progress, recipe.name)
    try:
        _run_blocks(recipe, todo, out_dir, attrs, workers, bar)
    finally:
        bar.close()
    missing = [p for p in blocks if not (out_dir / p.split / shard_file_name(p.shard_index)).exists()]
    if missing:
        _log.info("%d of %d blocks still missing; manifest not written yet", len(missing), len(blocks))
        return None
    manifest = build_manifest(out_dir)
    write_manifest(manifest, out_dir)
    problems = verify_manifest(out_dir, manifest)
    if problems:
        raise ManifestError(f"{out_dir}: the written dataset does not verify: {problems[0]}")
    return manifest
