"""ShardWriter: write CaptureSamples into HDF5 shards atomically (tmp file, fsync, rename), rolling over by count or size."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.fileio import fsync_dir, reserve_space, trim_reserve
from gttdata.shards.digest import ATTRS_DIGEST, attrs_digest
from gttdata.shards.schema import (
    COMPRESSIONS,
    GT_TOLERANCE_M,
    SAMPLE_FIELDS,
    SAMPLES_GROUP,
    SCHEMA_VERSION,
    TMP_SUFFIX,
    VARIANT_FIELDS,
    VARIANTS_GROUP,
    FieldSpec,
    dataset_kwargs,
    sample_group_name,
    shard_file_name,
)

__all__ = ["ShardInfo", "ShardWriter", "merge_stats", "sample_stats", "variant_from_orig"]

_log = logging.getLogger(__name__)

# Disk space reserved per sample on top of its raw array bytes: object headers, attributes, B-trees.
_SAMPLE_MARGIN_BYTES = 1 << 18

# A variant's ground truth is recomputed from the original's; it must agree with what the augmentation
# produced to well below the GT precision promise (1e-6 m).
_VARIANT_GT_TOL_M = 1e-9


@dataclass(frozen=True)
class ShardInfo:
    """A finished shard file.

    Args:
        path: Final path of the file.
        split: Split name.
        shard_index: Block index k.
        part: Part within the block (0 unless the block rolled over by bytes).
        first_index: Split-level index of the first sample.
        n_samples: Number of samples.
        bytes: File size in bytes.
    """

    path: Path
    split: str
    shard_index: int
    part: int
    first_index: int
    n_samples: int
    bytes: int


def variant_from_orig(sample: CaptureSample) -> np.ndarray:
    """The variant's rigid transform from the original capture, shape ``(4, 4)`` float64 (identity for orig)."""
    T = sample.meta.get("variant_from_orig") if sample.variant != "orig" else None
    return np.eye(4) if T is None else np.asarray(T, dtype=np.float64).reshape(4, 4)


def sample_stats(sample: CaptureSample) -> dict:
    """Additive statistics of one original sample (summed per shard, then per split in the manifest)."""
    sigma = sample.meta.get("capture", {}).get("sigma_px", sample.meta.get("sigma_px"))
    return {
        "n_samples": 1,
        "n_images": sample.n_images,
        "n_joint_slots": int(sample.visible.size),
        "n_visible": int(sample.visible.sum()),
        "n_images_min": sample.n_images,
        "n_images_max": sample.n_images,
        "sigma_px_sum": float(sigma) if sigma is not None else 0.0,
        "sigma_px_n": 0 if sigma is None else 1,
    }


def merge_stats(a: dict, b: dict) -> dict:
    """Combine two :func:`sample_stats` dicts (sums, min and max)."""
    if not a:
        return dict(b)
    if not b:
        return dict(a)
    out = {k: a[k] + b[k] for k in a if k not in ("n_images_min", "n_images_max")}
    out["n_images_min"] = min(a["n_images_min"], b["n_images_min"])
    out["n_images_max"] = max(a["n_images_max"], b["n_images_max"])
    return out


def _json(obj: object) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"))


def _check_variant(orig: CaptureSample, var: CaptureSample) -> None:
    """A stored variant may differ from the original only in the fields of VARIANT_FIELDS."""
    where = f"sample {orig.name!r} variant {var.variant!r}"
    for key in ("cam_id", "timestamp_s", "stream_index", "global_order", "image_size", "affinity_nbr"):
        if not np.array_equal(getattr(orig, key), getattr(var, key)):
            raise ValueError(f"{where}: {key} must equal the original's (variants share the ground truth)")
    T = variant_from_orig(var)
    expect = orig.points3d @ T[:3, :3].T + T[:3, 3]
    err = float(np.max(np.abs(expect - var.points3d), initial=0.0))
    if err > _VARIANT_GT_TOL_M:
        raise ValueError(
            f"{where}: points3d must equal variant_from_orig . orig points3d to {_VARIANT_GT_TOL_M} m, "
            f"found max error {err:.3g} m"
        )


class ShardWriter:
    """Write samples into ``out_dir/shard-XXXXX.h5`` files, each first written as ``.h5.tmp``.

    A file is renamed to its final name only after it was closed and fsynced, so a killed run never
    leaves a file with a final name that is incomplete. After each sample the writer rolls over to a new
    file when the file holds ``max_samples`` samples or when one more sample of the size of the last one
    would exceed ``max_bytes``. Both depend only on the content, so identical input gives identical files.

    Example::

        with ShardWriter(out_dir, split="train", max_samples=256) as w:
            for group in samples:  # [orig, *variants] from gttdata.generate_plan.build_sample
                w.write(group)

    Args:
        out_dir: Directory of the shard files (created).
        split: Split name (root attribute).
        shard_index: Index of the first file (``shard-{shard_index:05d}.h5``).
        first_index: Split-level index of the first sample written.
        max_samples: Samples per file before rolling over.
        max_bytes: Roll over before a file would exceed this size.
        compression: One of :data:`~gttdata.shards.schema.COMPRESSIONS`.
        attrs: Extra root attributes (``generator``, ``recipe_hash``, ``recipe``...); strings or numbers.
        parts: False: a rollover starts file ``shard_index + 1``. True: every file belongs to block
            ``shard_index`` and a rollover starts part ``p + 1`` (``shard-00003.p1.h5``); used by
            :func:`gttdata.generation.generate_dataset` so a block's file names never depend on other blocks.
        rename_on_close: False: finished files keep their ``.tmp`` name until :meth:`commit` (used to
            rename all parts of a block together).
    """

    def __init__(
        self,
        out_dir: str | Path,
        *,
        split: str,
        shard_index: int = 0,
        first_index: int = 0,
        max_samples: int = 256,
        max_bytes: int = 1 << 30,
        compression: str = "gzip",
        attrs: dict | None = None,
        parts: bool = False,
        rename_on_close: bool = True,
    ) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {COMPRESSIONS}, got {compression!r}")
        if max_samples < 1 or max_bytes < 1:
            raise ValueError(f"max_samples and max_bytes must be >= 1, got {max_samples}, {max_bytes}")
        self.out_dir = Path(out_dir)
        self.split = split
        self.compression = compression
        self.max_samples = int(max_samples)
        self.max_bytes = int(max_bytes)
        self.attrs = dict(attrs or {})
        self.parts = parts
        self.rename_on_close = rename_on_close
        self._index = int(shard_index)
        self._part = 0
        self._next_sample = int(first_index)
        self._file: h5py.File | None = None
        self._tmp: Path | None = None
        self._n = 0
        self._first = self._next_sample
        self._variants: list[str] | None = None
        self._stats: dict = {}
        self._skeleton = ""
        self._pending: list[tuple[Path, ShardInfo]] = []
        self.finished: list[ShardInfo] = []

    def __enter__(self) -> ShardWriter:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- public ---------------------------------------------------------------------------------------

    def write(self, sample: CaptureSample | Sequence[CaptureSample]) -> None:
        """Append one sample, optionally with its capture-level variants.

        Args:
            sample: A CaptureSample (its ``variant`` must be ``"orig"``), or ``[orig, *variants]`` where
                each variant shares the original's images and timing and has
                ``points3d == variant_from_orig . orig.points3d``.

        Raises:
            ValueError: A variant that does not share the original's ground truth, or variant names
                differing from the shard's other samples.
        """
        group = [sample] if isinstance(sample, CaptureSample) else list(sample)
        orig, variants = group[0], group[1:]
        if orig.variant != "orig":
            raise ValueError(
                f"sample {orig.name!r}: the first sample must be variant 'orig', got {orig.variant!r}"
            )
        names = ["orig"] + [v.variant for v in variants]
        if len(set(names)) != len(names):
            raise ValueError(f"sample {orig.name!r}: variant names must be unique, got {names}")
        for var in variants:
            _check_variant(orig, var)
        if self._file is None:
            self._open()
        if self._variants is None:
            self._variants = names
        elif names != self._variants:
            raise ValueError(
                f"sample {orig.name!r}: every sample of a shard must hold variants {self._variants}, got {names}"
            )
        f = self._file
        assert f is not None  # opened above
        before = f.id.get_filesize()
        # HDF5 does not survive a failed write (a full disk segfaulted the process): reserve the space
        # first, so a full disk is one clean error here and the writes below cannot fail for space.
        need = _SAMPLE_MARGIN_BYTES + sum(_nbytes(s) for s in group)
        reserve_space(f.id.get_vfd_handle(), before, need, self._path())
        self._write_group(f[SAMPLES_GROUP], self._next_sample, orig, variants)
        self._stats = merge_stats(self._stats, sample_stats(orig))
        if not self._skeleton:
            self._skeleton = _json(orig.skeleton.to_dict())
        self._skeletons[orig.skeleton.name] = self._skeletons.get(orig.skeleton.name, 0) + 1
        self._n += 1
        self._next_sample += 1
        f.flush()
        size = f.id.get_filesize()
        if self._n >= self.max_samples or size + (size - before) > self.max_bytes:
            self._finish()

    def close(self) -> list[ShardInfo]:
        """Finish the open file and rename every finished file; returns all files written."""
        if self._file is not None:
            self._finish()
        self.commit()
        return list(self.finished)

    def commit(self) -> None:
        """Rename finished ``.tmp`` files to their final names, last first, and fsync the directory.

        Renaming the first file last means that, with ``parts=True``, ``shard-0000k.h5`` exists only
        once every part of block k does.
        """
        for tmp, info in reversed(self._pending):
            os.replace(tmp, info.path)
            _log.debug("wrote %s (%d samples, %d bytes)", info.path, info.n_samples, info.bytes)
        self.finished.extend(info for _, info in self._pending)
        if self._pending:
            fsync_dir(self.out_dir)
        self._pending = []

    def abort(self) -> None:
        """Close and delete every unfinished or uncommitted ``.tmp`` file (finished files are kept)."""
        tmps: list[Path | None] = [tmp for tmp, _ in self._pending]
        if self._file is not None:
            try:
                self._file.close()
            except Exception:  # noqa: BLE001 - the file is deleted anyway; keep the original error
                _log.debug("closing %s after an error failed", self._tmp)
            self._file = None
        tmps.append(self._tmp)  # also a closed file whose fsync failed
        self._tmp = None
        for tmp in tmps:
            if tmp is not None and tmp.exists():
                tmp.unlink()
        self._pending = []

    # -- internals ------------------------------------------------------------------------------------

    def _path(self) -> Path:
        if self.parts:
            return self.out_dir / shard_file_name(self._index, self._part)
        return self.out_dir / shard_file_name(self._index)

    def _open(self) -> None:
        self._tmp = self._path().with_name(self._path().name + TMP_SUFFIX)
        # libver v110: compact, deterministic object headers; readable by HDF5 >= 1.10.
        self._file = h5py.File(self._tmp, "w", libver=("v110", "v110"))
        _create_group(self._file, SAMPLES_GROUP)
        self._n, self._first, self._variants, self._stats, self._skeleton = 0, self._next_sample, None, {}, ""
        self._skeletons: dict[str, int] = {}

    def _write_group(
        self, parent: h5py.Group, index: int, orig: CaptureSample, variants: list[CaptureSample]
    ) -> None:
        g = _create_group(parent, sample_group_name(index))
        g.attrs["name"] = orig.name
        g.attrs["motion_name"] = orig.motion_name
        g.attrs["skeleton"] = _json(orig.skeleton.to_dict())
        g.attrs["meta"] = _json(orig.meta)
        g.attrs["index"] = np.int64(index)
        for spec in SAMPLE_FIELDS:
            _write_array(g, spec, getattr(orig, spec.name), self.compression)
        if not variants:
            return
        vg = _create_group(g, VARIANTS_GROUP)
        for var in variants:
            v = _create_group(vg, var.variant)
            v.attrs["meta"] = _json(var.meta)
            for spec in VARIANT_FIELDS:
                data = variant_from_orig(var) if spec.name == "variant_from_orig" else getattr(var, spec.name)
                _write_array(v, spec, data, self.compression)

    def _finish(self) -> None:
        f, tmp = self._file, self._tmp
        assert f is not None and tmp is not None  # only called with a shard open
        f.attrs["schema_version"] = SCHEMA_VERSION
        for key, value in self.attrs.items():
            f.attrs[key] = value
        f.attrs["split"] = self.split
        f.attrs["shard_index"] = np.int64(self._index)
        f.attrs["part"] = np.int64(self._part if self.parts else 0)
        f.attrs["first_index"] = np.int64(self._first)
        f.attrs["n_samples"] = np.int64(self._n)
        f.attrs["variants"] = _json(self._variants or ["orig"])
        f.attrs["stats"] = _json(self._stats)
        f.attrs["skeleton"] = self._skeleton
        f.attrs["skeletons"] = _json(self._skeletons)
        f.attrs[ATTRS_DIGEST] = attrs_digest(f)  # last: it covers every attribute above and the samples'
        f.close()
        self._file = None
        trim_reserve(tmp)
        _fsync_file(tmp)
        info = ShardInfo(
            path=self._path(),
            split=self.split,
            shard_index=self._index,
            part=self._part if self.parts else 0,
            first_index=self._first,
            n_samples=self._n,
            bytes=tmp.stat().st_size,
        )
        self._pending.append((tmp, info))
        self._tmp = None
        if self.rename_on_close:
            self.commit()
        if self.parts:
            self._part += 1
        else:
            self._index += 1


def _nbytes(sample: CaptureSample) -> int:
    """Raw bytes of a sample's arrays (an upper bound of what a compressed write adds, bar metadata)."""
    values = (getattr(sample, f.name) for f in dataclasses.fields(sample))
    return sum(v.nbytes for v in values if isinstance(v, np.ndarray))


def _create_group(parent: h5py.Group, name: str) -> h5py.Group:
    """A group without modification times (identical content must give identical bytes)."""
    gcpl = h5py.h5p.create(h5py.h5p.GROUP_CREATE)
    gcpl.set_obj_track_times(False)
    return h5py.Group(h5py.h5g.create(parent.id, name.encode(), gcpl=gcpl))


def _write_array(group: h5py.Group, spec: FieldSpec, data: np.ndarray, compression: str) -> None:
    arr = np.ascontiguousarray(data, dtype=np.dtype(spec.dtype))
    if spec.lossy:
        full = np.asarray(data, dtype=np.float64)
        err = np.max(np.abs(arr.astype(np.float64) - full), initial=0.0)
        if not err <= GT_TOLERANCE_M:  # also catches NaN; keep full precision then
            arr = np.ascontiguousarray(full)
    kw = dataset_kwargs(compression, arr.shape, compress=spec.compress)
    group.create_dataset(spec.name, data=arr, **kw)


def _fsync_file(path: Path) -> None:
    """Flush a closed file's data to disk (the rename that follows must not outrun it)."""
    with open(path, "rb+") as fh:
        os.fsync(fh.fileno())
