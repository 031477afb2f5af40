"""Fetch the free CMU BVH clips and Vicon C3D trials shipped in Debian packages into a user cache.

Sources (CMU data: free for research and commercial use, acknowledge mocap.cs.cmu.edu):
    * ``assimp-testmodels``: ``usr/share/assimp/models/BVH/{01_01,01_03,Boxing_Toes}.bvh``.
    * ``dart-doc``: ``usr/share/doc/dart/data/c3d/{nick_freeform_001,squat}.c3d`` (possibly ``.c3d.gz``).

No root is needed: installed copies under ``/usr/share`` are used when present, else the package
is fetched with ``apt-get download`` into a temporary directory and unpacked with ``dpkg-deb -x``.
"""

from __future__ import annotations

import gzip
import logging
import os
import shutil
import subprocess
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from gttdata.errors import GttDataError

__all__ = [
    "MOTION_FILES",
    "SYSTEM_ROOT",
    "MotionFile",
    "cache_dir",
    "default_cache_dir",
    "fetch_motions",
    "list_cached",
]

_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MotionFile:
    """One fetchable motion file.

    Args:
        name: File name in the cache.
        package: Debian package that ships it.
        member: Path inside the package (relative to ``/``), without a ``.gz`` suffix.
    """

    name: str
    package: str
    member: str


_BVH_DIR = "usr/share/assimp/models/BVH"
_C3D_DIR = "usr/share/doc/dart/data/c3d"

#: The files ``gttdata motions fetch`` provides.
MOTION_FILES: tuple[MotionFile, ...] = (
    MotionFile("01_01.bvh", "assimp-testmodels", f"{_BVH_DIR}/01_01.bvh"),
    MotionFile("01_03.bvh", "assimp-testmodels", f"{_BVH_DIR}/01_03.bvh"),
    MotionFile("Boxing_Toes.bvh", "assimp-testmodels", f"{_BVH_DIR}/Boxing_Toes.bvh"),
    MotionFile("nick_freeform_001.c3d", "dart-doc", f"{_C3D_DIR}/nick_freeform_001.c3d"),
    MotionFile("squat.c3d", "dart-doc", f"{_C3D_DIR}/squat.c3d"),
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


def _copy_member(root: Path, member: str, dest: Path) -> bool:
    """Copy ``root/member`` (or its ``.gz``, decompressed) to ``dest`` atomically; False if absent."""
    src, gz = root / member, root / f"{member}.gz"
    tmp = dest.with_name(dest.name + ".tmp")
    if src.is_file():
        shutil.copyfile(src, tmp)
    elif gz.is_file():
        with gzip.open(gz, "rb") as fin, tmp.open("wb") as fout:
            shutil.copyfileobj(fin, fout)
    else:
        return False
    tmp.replace(dest)
    return True


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
    files: tuple[MotionFile, ...] = MOTION_FILES,
    progress: Callable[[str], None] | None = None,
) -> list[Path]:
    """Make every file of ``files`` present in ``dest``; files already there are kept (idempotent).

    Args:
        dest: Cache directory; defaults to :func:`cache_dir`.
        system_root: Where installed packages live; defaults to :data:`SYSTEM_ROOT`.
        files: Which files to fetch.
        progress: Called with one human-readable line per step (the CLI passes ``click.echo``);
            every line is also logged at INFO.

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
    for f in files:
        if (dest / f.name).is_file():
            say(f"{f.name}: already cached")
        elif _copy_member(root, f.member, dest / f.name):
            say(f"{f.name}: copied from the installed package {f.package} ({root / f.member})")
        else:
            todo.append(f)
    for package in dict.fromkeys(f.package for f in todo):
        say(f"{package}: not installed; running 'apt-get download {package}' and 'dpkg-deb -x'")
        with tempfile.TemporaryDirectory(prefix="gtt-fetch-") as tmp:
            unpacked = _unpack_package(package, Path(tmp))
            for f in (f for f in todo if f.package == package):
                if not _copy_member(unpacked, f.member, dest / f.name):
                    raise GttDataError(f"package {package!r} does not contain {f.member} (or {f.member}.gz)")
                say(f"{f.name}: unpacked from {package}")
    return [dest / f.name for f in files]


def list_cached(cache: str | Path | None = None) -> list[Path]:
    """Motion files (by suffix) in the cache directory, sorted by name; empty if it does not exist."""
    cache = Path(cache) if cache is not None else cache_dir()
    if not cache.is_dir():
        return []
    return sorted(p for p in cache.iterdir() if p.is_file() and p.suffix.lower() in _MOTION_SUFFIXES)
