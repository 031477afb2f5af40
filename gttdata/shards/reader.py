"""ShardReader: lazy, picklable random access to the CaptureSamples of one HDF5 shard."""

from __future__ import annotations

import errno
import json
import logging
import os
from pathlib import Path

import h5py
import numpy as np
from h5py import h5d, h5g, h5s

from gttdata.capture.sample import CaptureSample
from gttdata.errors import MotionFormatError, ShardFormatError
from gttdata.shards.digest import ATTRS_DIGEST, attrs_digest
from gttdata.shards.schema import (
    ATTRS_DIGEST_SINCE_MINOR,
    SAMPLE_FIELDS,
    SAMPLES_GROUP,
    VARIANT_FIELDS,
    VARIANTS_GROUP,
    check_schema_version,
)
from gttdata.skeleton import Skeleton

__all__ = ["ShardReader"]

_log = logging.getLogger(__name__)

# What h5py raises on damaged HDF5 metadata (a bad object header checksum is a KeyError, a truncated
# heap an OSError, text that is no longer UTF-8 a UnicodeDecodeError, a ValueError).
_H5_ERRORS = (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError)

# Shards without an attribute checksum (schema < 1.2) this process was warned about (at most one).
_WARNED_UNCHECKED: list[str] = []

# In-memory dtypes of the CaptureSample fields (the stored dtype may be narrower; see schema.py).
_MEMORY_DTYPES = {
    "cam_id": np.int32,
    "timestamp_s": np.float64,
    "stream_index": np.int32,
    "global_order": np.int32,
    "keypoints_px": np.float32,
    "visible": np.bool_,
    "keypoints_gt_px": np.float32,
    "K": np.float64,
    "cam_from_world": np.float64,
    "image_size": np.int32,
    "points3d": np.float64,
    "affinity_nbr": np.int32,
    "affinity_w": np.float64,
    "variant_from_orig": np.float64,
}


def _attr_str(attrs: h5py.AttributeManager, key: str, where: str) -> str:
    if key not in attrs:
        raise ShardFormatError(f"{where}: attribute {key!r} is missing")
    value = attrs[key]
    return value.decode() if isinstance(value, bytes) else str(value)


def _attr_json(attrs: h5py.AttributeManager, key: str, where: str):
    text = _attr_str(attrs, key, where)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ShardFormatError(
            f"{where}: attribute {key!r}: expected JSON, found {text[:40]!r} ({exc})"
        ) from exc


class ShardReader:
    """Read samples of one shard by local index; the HDF5 file is opened on first access.

    The handle belongs to the process that opened it: after a fork, or when the reader is unpickled in
    a DataLoader worker, the file is reopened there. Pickling never carries the handle.

    Args:
        path: A ``shard-XXXXX.h5`` file.

    Raises:
        ShardFormatError: (on first access) the file is not a readable shard, is truncated, or has an
            unknown major schema version; reading a corrupt sample names the shard, sample and field.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._file: h5py.File | None = None
        self._samples: h5py.Group | None = None
        self._pid: int | None = None
        self._attrs: dict | None = None
        self._names: list[str] | None = None

    # -- pickling and lifetime -----------------------------------------------------------------------

    def __getstate__(self) -> dict:
        return {"path": self.path, "_attrs": self._attrs, "_names": self._names}

    def __setstate__(self, state: dict) -> None:
        ShardReader.__init__(self, state["path"])
        self._attrs, self._names = state["_attrs"], state["_names"]

    def __enter__(self) -> ShardReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()

    def close(self) -> None:
        """Close the handle if this process opened it (reopened on next access)."""
        f = getattr(self, "_file", None)
        if f is not None and self._pid == os.getpid():
            try:
                f.close()
            except Exception:  # noqa: BLE001 - closing during interpreter shutdown may fail harmlessly
                pass
        self._file = None
        self._samples = None

    def _where(self, i: int | None = None, name: str | None = None) -> str:
        where = f"{self.path}"
        if i is not None:
            where += f": sample {i}"
            if name is not None:
                where += f" (group {SAMPLES_GROUP}/{name})"
        return where

    @property
    def file(self) -> h5py.File:
        """The open h5py handle of this process."""
        if self._file is None or self._pid != os.getpid():
            self._open()
        return self._file

    def _open(self) -> None:
        try:
            f = h5py.File(self.path, "r")
        except FileNotFoundError as exc:  # h5py leaves filename None: name the shard here
            raise FileNotFoundError(
                errno.ENOENT,
                "shard file is missing (regenerate it: gttdata generate ... --resume)",
                str(self.path),
            ) from exc
        except OSError as exc:
            raise ShardFormatError(f"{self.path}: cannot open shard ({_short(exc)})") from exc
        try:
            check_schema_version(f.attrs.get("schema_version"), source=str(self.path))
            if SAMPLES_GROUP not in f:
                raise ShardFormatError(f"{self.path}: group {SAMPLES_GROUP!r} is missing")
            if self._names is None:
                names = sorted(f[SAMPLES_GROUP].keys())
                n = int(f.attrs.get("n_samples", -1))
                if n != len(names):
                    raise ShardFormatError(
                        f"{self.path}: attribute n_samples: expected {len(names)} (groups present), found {n}"
                    )
                self._names = names
            samples = f[SAMPLES_GROUP]
        except ShardFormatError:
            f.close()
            raise
        except _H5_ERRORS as exc:
            f.close()
            raise ShardFormatError(f"{self.path}: unreadable shard metadata ({_short(exc)})") from exc
        self._file, self._pid = f, os.getpid()
        self._samples = samples

    # -- metadata ------------------------------------------------------------------------------------

    @property
    def attrs(self) -> dict:
        """Root attributes as plain Python values (JSON attributes decoded)."""
        if self._attrs is None:
            raw = self.file.attrs
            out = {}
            try:
                for key in raw:
                    value = raw[key]
                    value = value.decode() if isinstance(value, bytes) else value
                    if key in ("variants", "stats", "recipe", "skeleton", "skeletons") and isinstance(
                        value, str
                    ):
                        value = _attr_json(raw, key, str(self.path)) if value else None
                    elif isinstance(value, np.generic):
                        value = value.item()
                    out[key] = value
            except _H5_ERRORS as exc:
                raise ShardFormatError(f"{self.path}: unreadable root attributes ({_short(exc)})") from exc
            self._attrs = out
        return self._attrs

    def check_attrs(self) -> None:
        """Verify the attribute checksum (root ``attrs_sha256``) against every attribute of the file.

        A shard of schema 1.0 or 1.1 has none: it is accepted, with a logged warning that its attribute
        text (sample metadata, skeletons, recipe, statistics) is unchecked.

        Raises:
            ShardFormatError: The checksum differs (a changed byte in attribute text), is missing from a
                shard of schema 1.2 or later, or an attribute cannot be read.
        """
        f = self.file
        try:
            found = f.attrs.get(ATTRS_DIGEST)
            version = f.attrs.get("schema_version")
            version = version.decode() if isinstance(version, bytes) else str(version)
            digest = attrs_digest(f)
        except _H5_ERRORS as exc:
            raise ShardFormatError(f"{self.path}: unreadable attributes ({_short(exc)})") from exc
        if found is None:
            minor = version.split(".")[1] if version.count(".") == 1 else ""
            if not minor.isdigit() or int(minor) >= ATTRS_DIGEST_SINCE_MINOR:
                raise ShardFormatError(
                    f"{self.path}: root attribute {ATTRS_DIGEST!r} is missing "
                    f"(schema {version} shards carry it); the attributes cannot be trusted"
                )
            if not _WARNED_UNCHECKED:  # once per process: a dataset has many shards of one schema
                _WARNED_UNCHECKED.append(str(self.path))
                _log.warning(
                    "warning: %s: schema %s shard has no attribute checksum; its metadata, skeleton, recipe "
                    "and statistics text is unchecked (regenerate it to add one; shown once, for the first "
                    "such shard)",
                    self.path,
                    version,
                )
            return
        found = found.decode(errors="replace") if isinstance(found, bytes) else str(found)
        if found != digest:
            raise ShardFormatError(
                f"{self.path}: {ATTRS_DIGEST}: expected {found[:16]}... (stored), found {digest[:16]}...; "
                "attribute text (sample metadata, skeleton, recipe or statistics) is corrupt"
            )

    def __len__(self) -> int:
        if self._names is None:
            self.file  # noqa: B018 - opening reads the sample list
        assert self._names is not None  # set by opening
        return len(self._names)

    def variants(self, i: int) -> tuple[str, ...]:
        """Variant names stored for local sample ``i``, ``"orig"`` first."""
        g = self._group(i)
        try:
            names = set(g[VARIANTS_GROUP].keys()) if VARIANTS_GROUP in g else set()
        except _H5_ERRORS as exc:
            raise ShardFormatError(
                f"{self._where(i)}: unreadable group {VARIANTS_GROUP!r} ({_short(exc)})"
            ) from exc
        order = [v for v in (self.attrs.get("variants") or ()) if v in names]
        return ("orig", *order, *sorted(names - set(order)))

    def sample_index(self, i: int) -> int:
        """Split-level index of local sample ``i``."""
        return int(self._name(i))

    # -- samples -------------------------------------------------------------------------------------

    def _name(self, i: int) -> str:
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"{self.path}: sample index {i} out of range for {n} samples")
        assert self._names is not None  # len() opened the file
        return self._names[i]

    def _group(self, i: int) -> h5py.Group:
        name = self._name(i)
        try:
            self.file  # noqa: B018 - (re)opens the file in this process, setting self._samples
            assert self._samples is not None
            return h5py.Group(h5g.open(self._samples.id, name.encode()))
        except (KeyError, OSError, RuntimeError) as exc:
            raise ShardFormatError(f"{self._where(i, name)}: unreadable group ({_short(exc)})") from exc

    def read_sample(self, i: int, variant: str = "orig") -> CaptureSample:
        """Read local sample ``i`` (or one of its variants) with every array in memory.

        Args:
            i: Local index in ``[0, len(self))`` (negative counts from the end).
            variant: ``"orig"`` or a name from :meth:`variants`.

        Returns:
            The CaptureSample, arrays with the in-memory dtypes documented on CaptureSample. A variant
            has the original's timing and ground truth, ``points3d = variant_from_orig . points3d``.

        Raises:
            KeyError: Unknown variant (the message lists the stored ones).
            ShardFormatError: A corrupt group, dataset or attribute, naming shard, sample and field.
        """
        name = self._name(i)
        where = self._where(i, name)
        if variant != "orig" and variant not in self.variants(i):
            raise KeyError(f"{where}: no variant {variant!r}; stored: {', '.join(self.variants(i))}")
        g = self._group(i)
        try:
            arrays = {spec.name: self._read(g, spec.name, where) for spec in SAMPLE_FIELDS}
            skeleton = self._skeleton(_attr_str(g.attrs, "skeleton", where), where)
            meta = _attr_json(g.attrs, "meta", where)
            if variant != "orig":
                vg = g[VARIANTS_GROUP][variant]
                vwhere = f"{where} variant {variant!r}"
                var = {spec.name: self._read(vg, spec.name, vwhere) for spec in VARIANT_FIELDS}
                T = var.pop("variant_from_orig")
                arrays.update(var)
                arrays["points3d"] = arrays["points3d"] @ T[:3, :3].T + T[:3, 3]
                meta = _attr_json(vg.attrs, "meta", vwhere)
            sample_name = _attr_str(g.attrs, "name", where)
            motion_name = _attr_str(g.attrs, "motion_name", where)
        except _H5_ERRORS as exc:
            raise ShardFormatError(f"{where}: unreadable metadata ({_short(exc)})") from exc
        try:
            return CaptureSample(
                name=sample_name,
                motion_name=motion_name,
                skeleton=skeleton,
                variant=variant,
                meta=meta,
                **arrays,
            )
        except ValueError as exc:
            raise ShardFormatError(f"{where}: inconsistent arrays ({exc})") from exc

    def _skeleton(self, text: str, where: str) -> Skeleton:
        """Parse a skeleton attribute once per distinct text (every sample of a shard usually shares one)."""
        cache = self.__dict__.setdefault("_skeletons", {})
        if text not in cache:
            try:
                cache[text] = Skeleton.from_dict(json.loads(text), source=where)
            except (MotionFormatError, *_H5_ERRORS) as exc:  # JSONDecodeError is a ValueError
                raise ShardFormatError(f"{where}: attribute 'skeleton': {_short(exc)}") from exc
        return cache[text]

    def _read(self, g: h5py.Group, key: str, where: str) -> np.ndarray:
        # The low-level calls skip h5py's per-object Python overhead: opening 13 datasets through
        # ``g[key][()]`` costs about twice the decoding itself (see docs/FORMAT.md, "Read speed").
        try:
            ds = h5d.open(g.id, key.encode())
            data = np.empty(ds.shape, dtype=ds.dtype)
            if data.size:
                ds.read(h5s.ALL, h5s.ALL, data)
        except KeyError as exc:
            raise ShardFormatError(f"{where}: field {key!r} is missing") from exc
        except (OSError, RuntimeError, ValueError, TypeError) as exc:
            raise ShardFormatError(
                f"{where}: field {key!r}: unreadable data, checksum or filter failed ({_short(exc)})"
            ) from exc
        want = np.dtype(_MEMORY_DTYPES[key])
        if data.dtype != want:
            if data.dtype.kind != want.kind:
                raise ShardFormatError(f"{where}: field {key!r}: expected dtype {want}, found {data.dtype}")
            data = data.astype(want)
        return data

    def check(self) -> None:
        """Verify the attribute checksum, then read every sample and variant (every Fletcher-32 chunk).

        Raises:
            ShardFormatError: Corrupt attribute text (see :meth:`check_attrs`), or the first corrupt
                sample, naming shard, sample and field.
        """
        self.check_attrs()
        for i in range(len(self)):
            for v in self.variants(i):
                try:
                    self.read_sample(i, v)
                except KeyError as exc:  # a variant listed by the file that cannot be opened
                    raise ShardFormatError(f"{self._where(i)}: variant {v!r}: {_short(exc)}") from exc


def _short(exc: BaseException) -> str:
    """The first line of an h5py error (they can be long)."""
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
