"""Fetch the free CMU BVH clips and Vicon C3D trials shipped in Debian packages into a user cache.

Sources (CMU data: free for research and commercial use, acknowledge mocap.cs.cmu.edu):
    * ``assimp-testmodels``: ``usr/share/assimp/models/BVH/{01_01,01_03,Boxing_Toes}.bvh``.
    * ``dart-doc``: ``usr/share/doc/dart/data/c3d/{nick_freeform_001,squat}.c3d`` (possibly ``.c3d.gz``).

No root is needed: installed copies under ``/usr/share`` are used when present, else the package
is fetched with ``apt-get download`` into a temporary directory and unpacked with ``dpkg-deb -x``.
"""

from __future__ import annotations

import gzip
import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from gttdata.errors import GttDataError
from gttdata.fileio import atomic_write, file_sha256

__all__ = [
    "MOTION_FILES",
    "SYSTEM_ROOT",
    "MotionFile",
    "cache_dir",
    "default_cache_dir",
    "fetch_motions",
    "list_cached",
    "check_cached",
]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MotionFile:
    """One fetchable motion file.

    Args:
        name: File name in the cache.
        package: Debian package that ships it.
        member: Path inside the package (relative to ``/``), without a ``.gz`` suffix.
        sha256: SHA-256 of the file (decompressed); None: not checked.
    """

    name: str
    package: str
    member: str
    sha256: str | None = None


_BVH_DIR = "usr/share/assimp/models/BVH"
_C3D_DIR = "usr/share/doc/dart/data/c3d"

#: The files ``gttdata motions fetch`` provides.
#: Checksums are those of the files in Debian 12 (bookworm): assimp-testmodels and dart-doc.
MOTION_FILES: tuple[MotionFile, ...] = (
    MotionFile(
        "01_01.bvh",
        "assimp-testmodels",
        f"{_BVH_DIR}/01_01.bvh",
        "1d9ee909452ee62784306545cf1fcd634243db1173e0c90cecbed793e50361a8",
    ),
    MotionFile(
        "01_03.bvh",
        "assimp-testmodels",
        f"{_BVH_DIR}/01_03.bvh",
        "72d3f37de5af9adfc228dda72422cadb8cfc58d1cd8336076241ba115715c87c",
    ),
    MotionFile(
        "Boxing_Toes.bvh",
        "assimp-testmodels",
        f"{_BVH_DIR}/Boxing_Toes.bvh",
        "ad81c1e3bb2349cb8ea5ac5d753b8a199fce9182bf9015bcc45c2f0414bc99af",
    ),
    MotionFile(
        "nick_freeform_001.c3d",
        "dart-doc",
        f"{_C3D_DIR}/nick_freeform_001.c3d",
        "071a483aae9ef3d6c41061de65236a9d54ab50c10fcd0cbbf9c4720580e7fae6",
    ),
    MotionFile(
        "squat.c3d",
        "dart-doc",
        f"{_C3D_DIR}/squat.c3d",
        "224bdcc89e802b87b3a0f3d1d505c7d3e14e5b71e97ac5884a25be1a270a8bbd",
    ),
)

#: Root of the installed system tree searched for packaged copies (tests point it elsewhere).
SYSTEM_ROOT = Path("/")

_MOTION_SUFFIXES = (".bvh", ".c3d", ".amc", ".asf", ".npz", ".h5", ".hdf5")


def cache_dir() -> Path:
    """The motion cache: ``$GTT_CACHE`` if set, else ``~/.cache/gtt/motions``."""
    env = os.environ.get("GTT_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "gtt" / "motions"


#: Alias of :func:`cache_dir`, kept for existing callers.
default_cache_dir = cache_dir


def _copy_member(root: Path, f: MotionFile, dest: Path) -> bool:
    """Copy ``root/member`` (or its ``.gz``, decompressed) to ``dest`` atomically; False if absent.

    Raises:
        GttDataError: The copy's SHA-256 differs from ``f.sha256`` (nothing is written then).
    """
    src, gz = root / f.member, root / f"{f.member}.gz"
    if not (src.is_file() or gz.is_file()):
        return False
    digest = hashlib.sha256()
    with atomic_write(dest, "wb") as fout:
        with open(src, "rb") if src.is_file() else gzip.open(gz, "rb") as fin:
            for block in iter(lambda: fin.read(1 << 20), b""):
                digest.update(block)
                fout.write(block)
        if f.sha256 is not None and digest.hexdigest() != f.sha256:
            raise GttDataError(
                f"{src if src.is_file() else gz}: sha256: expected {f.sha256[:16]}... for {f.name}, found "
                f"{digest.hexdigest()[:16]}... (another package version?); not cached"
            )
    return True


def _cached_ok(path: Path, f: MotionFile) -> str | None:
    """Why the cached copy of ``f`` cannot be used (None when it is present and intact)."""
    if not path.is_file():
        return "missing"
    if f.sha256 is None:
        return None
    found = file_sha256(path)
    return None if found == f.sha256 else f"sha256 {found[:16]}..., expected {f.sha256[:16]}..."


def check_cached(path: str | Path, cache: str | Path | None = None) -> None:
    """Refuse a file of the motion cache whose SHA-256 is not the one :data:`MOTION_FILES` records.

    Files outside the cache, and cache files of other names, are not checked here (a recipe's own
    motion files carry no published checksum).

    Raises:
        GttDataError: One line naming the file, the expected and the found digest, and the fix.
    """
    path = Path(path)
    cache = Path(cache) if cache is not None else cache_dir()
    try:
        inside = path.resolve().parent == cache.resolve()
    except OSError:
        return
    known = next((f for f in MOTION_FILES if f.name == path.name and f.sha256), None) if inside else None
    if known is None:
        return
    why = _cached_ok(path, known)
    if why is not None:
        raise GttDataError(
            f"{path}: cached motion file {known.name}: {why} (damaged or replaced); "
            "fetch it again with: gttdata motions fetch"
        )


def _run(cmd: list[str], cwd: Path, what: str) -> None:
    try:
        proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=600, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise GttDataError(f"{what} failed: {exc}") from exc
    if proc.returncode != 0:
        lines = (proc.stderr or proc.stdout).strip().splitlines()
        detail = lines[-1] if lines else f"exit status {proc.returncode}"
        raise GttDataError(
            f"{what} failed ({detail}); install the package or copy the files into the cache by hand"
        )


def _unpack_package(package: str, workdir: Path) -> Path:
    """``apt-get download`` + ``dpkg-deb -x`` into ``workdir``; returns the unpacked root."""
    for tool in ("apt-get", "dpkg-deb"):
        if shutil.which(tool) is None:
            raise GttDataError(
                f"cannot fetch Debian package {package!r}: {tool} not found; on a Debian/Ubuntu system run "
                f"'apt-get download {package}', or copy its files into the cache by hand"
            )
    _run(["apt-get", "download", package], workdir, f"'apt-get download {package}'")
    debs = sorted(workdir.glob(f"{package}_*.deb"))
    if not debs:
        raise GttDataError(f"'apt-get download {package}' produced no {package}_*.deb in {workdir}")
    root = workdir / "root"
    root.mkdir(exist_ok=True)
    _run(["dpkg-deb", "-x", str(debs[-1]), str(root)], workdir, f"'dpkg-deb -x {debs[-1].name}'")
    return root


def fetch_motions(
    dest: str | Path | None = None,
    *,
    system_root: str | Path | None = None,
    files: tuple[MotionFile, ...] | None = None,
    progress: Callable[[str], None] | None = None,
    force: bool = False,
) -> list[Path]:
    """Make every file of ``files`` present and intact in ``dest`` (idempotent).

    A cached file is kept when its SHA-256 matches; a damaged one (truncated, garbage) is fetched
    again. Every copy is checked before it is renamed into the cache.

    Args:
        dest: Cache directory; defaults to :func:`cache_dir`.
        system_root: Where installed packages live; defaults to :data:`SYSTEM_ROOT`.
        files: Which files to fetch (default :data:`MOTION_FILES`).
        progress: Called with one human-readable line per step (the CLI passes ``click.echo``);
            every line is also logged at INFO.
        force: Fetch every file again, even when its cached copy is intact.

    Returns:
        Paths of all requested files in ``dest``.

    Raises:
        GttDataError: A package could not be downloaded or lacks a file (one line).
    """

    def say(msg: str) -> None:
        _log.info("%s", msg)
        if progress is not None:
            progress(msg)

    dest = Path(dest) if dest is not None else cache_dir()
    dest.mkdir(parents=True, exist_ok=True)
    root = Path(system_root) if system_root is not None else SYSTEM_ROOT
    todo = []
    files = MOTION_FILES if files is None else files
    for f in files:
        why = "--force" if force else _cached_ok(dest / f.name, f)
        if why is None:
            say(f"{f.name}: already cached" + (" (sha256 verified)" if f.sha256 else ""))
            continue
        if why not in ("missing", "--force"):
            say(f"{f.name}: cached copy is damaged ({why}); fetching it again")
        if _copy_member(root, f, dest / f.name):
            say(f"{f.name}: copied from the installed package {f.package} ({root / f.member})")
        else:
            todo.append(f)
    for package in dict.fromkeys(f.package for f in todo):
        say(f"{package}: not installed; running 'apt-get download {package}' and 'dpkg-deb -x'")
        with tempfile.TemporaryDirectory(prefix="gtt-fetch-") as tmp:
            unpacked = _unpack_package(package, Path(tmp))
            for f in (f for f in todo if f.package == package):
                if not _copy_member(unpacked, f, dest / f.name):
                    raise GttDataError(f"package {package!r} does not contain {f.member} (or {f.member}.gz)")
                say(f"{f.name}: unpacked from {package}")
    return [dest / f.name for f in files]


def list_cached(cache: str | Path | None = None) -> list[Path]:
    """Motion files (by suffix) in the cache directory, sorted by name; empty if it does not exist."""
    cache = Path(cache) if cache is not None else cache_dir()
    if not cache.is_dir():
        return []
    return sorted(p for p in cache.iterdir() if p.is_file() and p.suffix.lower() in _MOTION_SUFFIXES)
