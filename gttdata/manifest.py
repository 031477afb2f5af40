"""The dataset manifest: what a dataset directory holds (shards with sizes and SHA-256, recipe, statistics), built, written, loaded and verified."""

from __future__ import annotations

import functools
import json
import logging
import os
import posixpath
import subprocess
from dataclasses import asdict, dataclass, field
from pathlib import Path

from gttdata.errors import ManifestError, ShardFormatError
from gttdata.shards.inventory import check_files, file_sha256, scan_shards, summarise_stats
from gttdata.shards.reader import ShardReader
from gttdata.shards.schema import SCHEMA_VERSION, TMP_SUFFIX
from gttdata.shards.writer import merge_stats

__all__ = [
    "MANIFEST_NAME",
    "MANIFEST_VERSION",
    "Manifest",
    "ShardEntry",
    "build_manifest",
    "file_sha256",
    "git_revision",
    "load_manifest",
    "register_manifest",
    "scan_shards",
    "verify_manifest",
    "write_manifest",
]

_log = logging.getLogger(__name__)

#: File name of the manifest inside a dataset directory.
MANIFEST_NAME = "manifest.json"
#: Version of the manifest's JSON layout (independent of the shard schema version).
MANIFEST_VERSION = "1.0"


@dataclass(frozen=True)
class ShardEntry:
    """One shard file of a dataset.

    Args:
        path: Path relative to the dataset directory, POSIX separators (``train/shard-00000.h5``).
        split: Split name.
        shard_index: Block index k (samples ``[k*S, (k+1)*S)`` of the split).
        part: Part of the block (0 unless it rolled over by bytes).
        first_index: Split-level index of its first sample.
        n_samples: Number of samples.
        bytes: File size in bytes.
        sha256: SHA-256 hex digest of the file.
    """

    path: str
    split: str
    shard_index: int
    part: int
    first_index: int
    n_samples: int
    bytes: int
    sha256: str


def _check_shard_path(source: str, i: int, path: object) -> None:
    """A shard path is relative, POSIX, normalised and stays inside the dataset (a manifest may come from anyone).

    Raises:
        ManifestError: ``../x``, ``/abs``, ``a/../b``, ``./a``, ``a//b``, backslashes, empty (one line).
    """
    ok = (
        isinstance(path, str)
        and path not in ("", ".")
        and "\\" not in path
        and "\0" not in path
        and not posixpath.isabs(path)
        and posixpath.normpath(path) == path
        and path != ".."
        and not path.startswith("../")
    )
    if not ok:
        raise ManifestError(
            f"{source}: shards[{i}].path: expected a relative path inside the dataset "
            f"(like 'train/shard-00000.h5'), found {path!r}"
        )


@dataclass(frozen=True)
class Manifest:
    """Everything a consumer needs to trust and index a dataset directory.

    Args:
        name: Dataset name (the recipe's ``name``).
        manifest_version: :data:`MANIFEST_VERSION`.
        schema_version: Shard schema version of every shard.
        generator: ``gttdata <version>`` that wrote the shards.
        git_sha: Commit of the gttdata checkout that built the manifest, or None outside git.
        git_dirty: Whether that checkout had uncommitted changes to tracked files (None outside git).
        recipe_hash: SHA-256 of the canonical recipe JSON (output_dir cleared), shared by every shard.
        seed: The recipe's root seed.
        recipe: The resolved recipe (all defaults filled in, output_dir cleared).
        skeleton: The skeleton of the samples (``Skeleton.to_dict()``).
        rig: The recipe's rig section.
        variants: Variant names of every sample, ``"orig"`` first.
        splits: Per split (recipe order): ``n_samples``, ``n_shards``, ``statistics``.
        statistics: Whole-dataset statistics (see :func:`build_manifest`).
        shards: Every shard, by split (recipe order), block and part.
    """

    name: str
    manifest_version: str
    schema_version: str
    generator: str
    git_sha: str | None
    git_dirty: bool | None
    recipe_hash: str
    seed: int | None
    recipe: dict
    skeleton: dict | None
    rig: dict
    variants: tuple[str, ...]
    splits: dict[str, dict]
    statistics: dict
    shards: tuple[ShardEntry, ...] = field(default=())

    def to_dict(self) -> dict:
        """Plain JSON-serialisable form (inverse of :meth:`from_dict`)."""
        d = asdict(self)
        d["variants"] = list(self.variants)
        return d

    @classmethod
    def from_dict(cls, d: dict, *, source: str = "<manifest>") -> Manifest:
        """Build from :meth:`to_dict` output.

        Raises:
            ManifestError: A missing or mistyped field, naming ``source`` and the field.
        """
        if not isinstance(d, dict):
            raise ManifestError(f"{source}: expected a JSON object, found {type(d).__name__}")
        names = [f for f in cls.__dataclass_fields__ if f != "shards"]
        missing = [k for k in names + ["shards"] if k not in d]
        if missing:
            raise ManifestError(
                f"{source}: field {missing[0]!r} is missing (expected fields: {', '.join(names)})"
            )
        major = str(d["manifest_version"]).split(".")[0]
        if major != MANIFEST_VERSION.split(".")[0]:
            raise ManifestError(
                f"{source}: manifest_version: expected {MANIFEST_VERSION.split('.')[0]}.x, found {d['manifest_version']!r}"
            )
        try:
            shards = tuple(ShardEntry(**s) for s in d["shards"])
        except TypeError as exc:
            raise ManifestError(
                f"{source}: shards: expected objects with {list(ShardEntry.__dataclass_fields__)} ({exc})"
            ) from exc
        for i, entry in enumerate(shards):
            _check_shard_path(source, i, entry.path)
        kw = {k: d[k] for k in names}
        kw["variants"] = tuple(kw["variants"])
        # JSON is written with sorted keys: restore the recipe's split order.
        order = [s.get("name") for s in (kw["recipe"] or {}).get("splits", ())]
        splits = kw["splits"]
        kw["splits"] = {
            k: splits[k]
            for k in sorted(splits, key=lambda k: (order.index(k) if k in order else len(order), k))
        }
        return cls(**kw, shards=shards)

    def split_names(self) -> tuple[str, ...]:
        """Split names in recipe order."""
        return tuple(self.splits)

    def shards_of(self, split: str | None = None) -> tuple[ShardEntry, ...]:
        """The shards of one split (all when None), in index order.

        Raises:
            ManifestError: Unknown split (the message lists the splits).
        """
        if split is None:
            return self.shards
        if split not in self.splits:
            raise ManifestError(
                f"dataset {self.name!r}: no split {split!r}; splits: {', '.join(self.splits)}"
            )
        return tuple(s for s in self.shards if s.split == split)

    def n_samples(self, split: str | None = None) -> int:
        """Number of samples of one split (all when None)."""
        return sum(s.n_samples for s in self.shards_of(split))


@functools.lru_cache(maxsize=1)
def git_revision() -> tuple[str | None, bool | None]:
    """``(sha, dirty)`` of the git checkout holding this package, ``(None, None)`` outside git."""
    here = Path(__file__).resolve().parent
    try:
        sha = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None, None
    return (sha or None), bool(dirty)


def _split_order(recipe: dict, found: set[str]) -> list[str]:
    order = [s["name"] for s in recipe.get("splits", ())] if recipe else []
    return order + sorted(found - set(order))


def _read_entry(root: Path, path: Path) -> tuple[ShardEntry, dict]:
    reader = ShardReader(path)
    try:
        try:
            reader.check()  # a manifest blesses only content whose attribute and chunk checksums hold
            attrs = reader.attrs
        except ShardFormatError as exc:
            raise ManifestError(
                f"{exc}; not indexing it: regenerate it (gttdata generate RECIPE --out {root} --resume)"
            ) from exc
    finally:
        reader.close()
    rel = path.relative_to(root).as_posix()
    split = attrs.get("split")
    if split != path.parent.name:
        raise ManifestError(
            f"{path}: attribute split: expected {path.parent.name!r} (its folder), found {split!r}"
        )
    missing = [k for k in ("shard_index", "part", "first_index", "n_samples") if k not in attrs]
    if missing:
        raise ShardFormatError(f"{path}: root attribute {missing[0]!r} is missing")
    entry = ShardEntry(
        path=rel,
        split=split,
        shard_index=int(attrs["shard_index"]),
        part=int(attrs["part"]),
        first_index=int(attrs["first_index"]),
        n_samples=int(attrs["n_samples"]),
        bytes=path.stat().st_size,
        sha256=file_sha256(path),
    )
    return entry, attrs


def _check_coverage(split: str, entries: list[ShardEntry], expected: int | None) -> None:
    """The split's shards hold samples 0..n-1 exactly once, in index order."""
    nxt = 0
    for e in entries:
        if e.first_index != nxt:
            what = "missing" if e.first_index > nxt else "duplicated"
            raise ManifestError(
                f"{e.path}: first_index: expected {nxt}, found {e.first_index} (samples {what} in split {split!r})"
            )
        nxt += e.n_samples
    if expected is not None and nxt != expected:
        raise ManifestError(
            f"split {split!r}: expected {expected} samples (recipe), found {nxt} in {len(entries)} shards; "
            "generate the missing shards (gttdata generate ... --resume)"
        )


def build_manifest(root: str | Path, *, name: str | None = None) -> Manifest:
    """Index the shards under ``root/<split>/`` into a manifest (does not write it).

    Every shard must carry the same recipe hash and a readable schema version, each split's shards
    must hold its samples ``0..n-1`` exactly once (``n`` from the recipe stored in the shards, when any),
    and every sample must read back with valid Fletcher-32 chunk checksums: the SHA-256 values of a
    manifest vouch only for content that was verified.

    Args:
        root: Dataset directory.
        name: Dataset name when the shards carry no recipe (default: the directory name).

    Returns:
        The manifest. ``statistics`` (per split and overall): ``n_samples``, ``n_images``,
        ``images_per_sample_{mean,min,max}``, ``missing_rate`` (fraction of joint slots not observed) and
        ``sigma_px_mean`` (mean 2-D noise std drawn per sample, pixels), from the original samples.

    Raises:
        ManifestError: No shards, shards of different recipes, samples missing or duplicated, or a
            shard whose chunk checksums fail.
        ShardFormatError: A shard that cannot be opened.
    """
    root = Path(root)
    paths, _ = scan_shards(root)
    if not paths:
        raise ManifestError(f"{root}: no shard files (expected {root}/<split>/shard-XXXXX.h5)")
    entries: list[tuple[ShardEntry, dict]] = []
    hashes: dict[str, Path] = {}
    first_attrs: dict = {}
    for p in paths:
        entry, attrs = _read_entry(root, p)
        entries.append((entry, attrs))
        hashes.setdefault(attrs.get("recipe_hash", ""), p)
        first_attrs = first_attrs or attrs
    if len(hashes) > 1:
        (h1, p1), (h2, p2) = list(hashes.items())[:2]
        raise ManifestError(
            f"{root}: shards of different recipes: {p1.name} has recipe_hash {h1[:12]}, {p2} has {h2[:12]}; "
            "use one output directory per recipe"
        )
    recipe = first_attrs.get("recipe") or {}
    expected = {s["name"]: int(s["n_samples"]) for s in recipe.get("splits", ())}
    order = _split_order(recipe, {e.split for e, _ in entries} | set(expected))
    entries.sort(key=lambda ea: (order.index(ea[0].split), ea[0].shard_index, ea[0].part))
    variants = tuple(first_attrs.get("variants") or ("orig",))
    splits: dict[str, dict] = {}
    total: dict = {}
    for split in order:
        mine = [(e, a) for e, a in entries if e.split == split]
        _check_coverage(split, [e for e, _ in mine], expected.get(split))
        stats: dict = {}
        skeletons: dict[str, int] = {}
        for e, a in mine:
            if tuple(a.get("variants") or ("orig",)) != variants and e.n_samples:
                raise ManifestError(
                    f"{e.path}: variants: expected {list(variants)}, found {a.get('variants')}"
                )
            stats = merge_stats(stats, a.get("stats") or {})
            for name, count in (a.get("skeletons") or {}).items():  # schema >= 1.1
                skeletons[name] = skeletons.get(name, 0) + int(count)
        total = merge_stats(total, stats)
        splits[split] = {
            "n_samples": sum(e.n_samples for e, _ in mine),
            "n_shards": len(mine),
            "statistics": summarise_stats(stats),
        }
        if skeletons:
            splits[split]["skeletons"] = dict(sorted(skeletons.items()))
    sha, dirty = git_revision()
    return Manifest(
        name=recipe.get("name") or name or root.resolve().name,
        manifest_version=MANIFEST_VERSION,
        schema_version=str(first_attrs.get("schema_version", SCHEMA_VERSION)),
        generator=str(first_attrs.get("generator", "")),
        git_sha=sha,
        git_dirty=dirty,
        recipe_hash=str(first_attrs.get("recipe_hash", "")),
        seed=recipe.get("seed"),
        recipe=recipe,
        skeleton=first_attrs.get("skeleton"),
        rig=recipe.get("rig") or {},
        variants=variants,
        splits=splits,
        statistics=summarise_stats(total),
        shards=tuple(e for e, _ in entries),
    )


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}{TMP_SUFFIX}")
    try:
        with open(tmp, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def _manifest_text(manifest: Manifest) -> str:
    return json.dumps(manifest.to_dict(), indent=2, sort_keys=True) + "\n"


def write_manifest(manifest: Manifest, root: str | Path) -> Path:
    """Write ``root/manifest.json`` atomically (temporary file, fsync, rename); returns its path.

    Concurrent writers of the same dataset write identical text, so whichever rename lands last is fine.
    """
    path = Path(root) / MANIFEST_NAME
    _atomic_write_text(path, _manifest_text(manifest))
    _log.info("wrote %s (%d shards, %d samples)", path, len(manifest.shards), manifest.n_samples())
    return path


def register_manifest(manifest: Manifest, manifests_dir: str | Path, *, location: str | Path) -> Path:
    """Copy a manifest to ``manifests_dir/<name>.json`` with the dataset's ``location`` added.

    Args:
        manifest: The dataset's manifest.
        manifests_dir: The repository's ``manifests/`` folder (must exist).
        location: Where the dataset lives (recorded as given).

    Raises:
        ManifestError: ``manifests_dir`` is not a directory.
    """
    folder = Path(manifests_dir)
    if not folder.is_dir():
        raise ManifestError(f"{folder}: expected the repository's manifests/ folder, found no directory")
    path = folder / f"{manifest.name}.json"
    data = {**manifest.to_dict(), "location": str(location)}
    _atomic_write_text(path, json.dumps(data, indent=2, sort_keys=True) + "\n")
    return path


def load_manifest(path: str | Path) -> Manifest:
    """Read a manifest from a file or from a dataset directory's ``manifest.json``.

    Raises:
        ManifestError: Missing file (with the command that builds it), invalid JSON, or bad fields.
    """
    path = Path(path)
    if path.is_dir():
        path = path / MANIFEST_NAME
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise ManifestError(
            f"{path}: no manifest; generation did not finish (gttdata generate ... --resume) "
            f"or build it from complete shards with: gttdata manifest {path.parent}"
        ) from exc
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ManifestError(f"{path}: not valid JSON (line {exc.lineno}: {exc.msg})") from exc
    if not isinstance(data, dict):
        raise ManifestError(f"{path}: expected a JSON object, found {type(data).__name__}")
    try:
        return Manifest.from_dict(data, source=str(path))
    except (TypeError, AttributeError, ValueError, KeyError) as exc:  # a field of the wrong type
        raise ManifestError(f"{path}: a manifest field has the wrong type ({exc})") from exc


def verify_manifest(root: str | Path, manifest: Manifest | None = None, *, deep: bool = False) -> list[str]:
    """Check the shards on disk against the manifest.

    Args:
        root: Dataset directory.
        manifest: The manifest (default: ``root/manifest.json``).
        deep: Also read every sample of every shard (verifies each chunk's Fletcher-32 checksum and the
            arrays' shapes); the SHA-256 check already detects any changed byte.

    Returns:
        One line per problem, naming the shard (empty when everything matches): missing files, size or
        SHA-256 mismatches, unreadable or unknown schema versions, unlisted shards, leftover ``.tmp``.

    Raises:
        ManifestError: The manifest itself is missing or malformed.
    """
    root = Path(root)
    manifest = manifest or load_manifest(root)
    return check_files(root, manifest.shards, deep=deep)
