"""Shard files on disk: find them, hash them, and check them against expected (path, bytes, SHA-256) entries."""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

from gttdata.errors import ShardFormatError
from gttdata.fileio import file_sha256
from gttdata.shards.reader import ShardReader
from gttdata.shards.schema import SHARD_SUFFIX, TMP_SUFFIX, check_schema_version

__all__ = ["check_files", "file_sha256", "scan_shards", "summarise_stats"]

_SHARD_RE = re.compile(r"^shard-\d{5}(\.p\d+)?" + re.escape(SHARD_SUFFIX) + "$")


def scan_shards(root: str | Path) -> tuple[list[Path], list[Path]]:
    """Shard files and leftover temporary files under ``root/<split>/``.

    Returns:
        ``(shards, temporaries)``, each sorted by path.
    """
    root = Path(root)
    shards = sorted(p for p in root.glob(f"*/shard-*{SHARD_SUFFIX}") if _SHARD_RE.match(p.name))
    tmps = sorted(root.glob(f"*/shard-*{SHARD_SUFFIX}{TMP_SUFFIX}"))
    return shards, tmps


def summarise_stats(stats: dict) -> dict:
    """Readable statistics from summed shard statistics."""
    if not stats:
        return {"n_samples": 0, "n_images": 0}
    n = stats["n_samples"]
    return {
        "n_samples": n,
        "n_images": stats["n_images"],
        "images_per_sample_mean": round(stats["n_images"] / max(n, 1), 3),
        "images_per_sample_min": stats["n_images_min"],
        "images_per_sample_max": stats["n_images_max"],
        "missing_rate": round(1.0 - stats["n_visible"] / max(stats["n_joint_slots"], 1), 6),
        "sigma_px_mean": round(stats["sigma_px_sum"] / stats["sigma_px_n"], 6)
        if stats["sigma_px_n"]
        else None,
    }


def check_files(root: str | Path, entries: Iterable, *, deep: bool = False) -> list[str]:
    """Compare shard files under ``root`` with expected entries.

    Args:
        root: Dataset directory.
        entries: Objects with ``path`` (relative, POSIX), ``bytes`` and ``sha256`` (manifest shard entries).
        deep: Also read every sample (each chunk's Fletcher-32 checksum, the arrays' shapes).

    Returns:
        One line per problem naming the shard: missing, size or SHA-256 mismatch, unreadable or unknown
        schema version, shard files not among ``entries``, leftover ``.tmp`` files.
    """
    root = Path(root)
    entries = list(entries)
    problems: list[str] = []
    for e in entries:
        path = root / e.path
        if not path.is_file():
            problems.append(f"{e.path}: missing (expected {e.bytes} bytes)")
            continue
        size = path.stat().st_size
        if size != e.bytes:
            problems.append(
                f"{e.path}: size: expected {e.bytes} bytes, found {size} (truncated or rewritten)"
            )
            continue
        digest = file_sha256(path)
        if digest != e.sha256:
            problems.append(
                f"{e.path}: sha256: expected {e.sha256[:16]}..., found {digest[:16]}... (corrupt)"
            )
            continue
        try:
            with ShardReader(path) as reader:
                check_schema_version(reader.attrs.get("schema_version"), source=e.path)
                if deep:
                    reader.check()
        except ShardFormatError as exc:
            problems.append(str(exc))
    listed = {e.path for e in entries}
    shards, tmps = scan_shards(root)
    for p in shards:
        rel = p.relative_to(root).as_posix()
        if rel not in listed:
            problems.append(f"{rel}: shard not listed in the manifest (from another run?)")
    for p in tmps:
        problems.append(f"{p.relative_to(root).as_posix()}: leftover temporary file of an interrupted run")
    return problems
