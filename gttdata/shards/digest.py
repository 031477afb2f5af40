"""The attribute checksum of a shard: one SHA-256 over every attribute of every group, stored in the root.

HDF5 checksums object headers and our Fletcher-32 filter checks array chunks, but the text of
variable-length string attributes lives in the global heap, which nothing checks: a flipped byte in a
sample's ``meta`` (``sigma_px`` 1.0 became 5.0) or in the root ``stats`` read back as valid JSON. The
digest closes that gap. It is computed from the attributes as h5py returns them, so it does not depend
on where HDF5 placed them in the file, and it is a pure function of the content: identical shards
still have identical bytes.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator

import h5py
import numpy as np

__all__ = ["ATTRS_DIGEST", "attrs_digest"]

#: Root attribute holding :func:`attrs_digest` of the file (schema >= 1.2).
ATTRS_DIGEST = "attrs_sha256"


def _groups(f: h5py.File) -> Iterator[tuple[str, h5py.Group]]:
    """``(path, group)`` of the root and every group below it, in path order (``/``, ``/samples/``, ...)."""
    found: list[str] = []

    def visit(name: bytes | str, info) -> None:
        if info.type == h5py.h5o.TYPE_GROUP:
            found.append(name.decode() if isinstance(name, bytes) else name)

    # One C-level walk that reports object types without opening every dataset (3x faster).
    h5py.h5o.visit(f.id, visit, info=True)
    for name in sorted(n for n in found if n not in (".", "")):
        yield f"/{name}/", f[name]


def _canonical(value: object) -> tuple[str, object]:
    """A type tag and a JSON-able form of one attribute value (bytes and numbers by their exact bytes)."""
    if isinstance(value, str):
        return "str", value
    if isinstance(value, bytes):
        return "bytes", value.hex()
    if isinstance(value, np.ndarray) and value.dtype.kind == "O":
        return f"object{list(value.shape)}", [_canonical(v) for v in value.ravel().tolist()]
    if isinstance(value, np.ndarray | np.generic):
        arr = np.asarray(value)
        return f"{arr.dtype.str}{list(arr.shape)}", arr.tobytes().hex()
    return type(value).__name__, repr(value)


def attrs_digest(f: h5py.File) -> str:
    """SHA-256 hex digest over every attribute (path, name, type, value) of every group of ``f``, in path order.

    The root's own :data:`ATTRS_DIGEST` is left out. Datasets carry no attributes in a shard and are
    not visited (their bytes are covered by Fletcher-32).

    Raises:
        OSError, KeyError, ValueError, RuntimeError: HDF5 cannot read an attribute (damaged metadata,
            or text that is no longer UTF-8); callers turn this into one line naming the shard.
    """
    h = hashlib.sha256()
    for path, group in [("/", f), *_groups(f)]:
        attrs = group.attrs
        for key in sorted(attrs.keys()):
            if path == "/" and key == ATTRS_DIGEST:
                continue
            tag, value = _canonical(attrs[key])
            h.update(json.dumps([path, key, tag, value], ensure_ascii=True).encode() + b"\n")
    return h.hexdigest()
