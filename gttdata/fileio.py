"""Safe writes shared by gttdata and gttnet: atomic files, checksums, one-line write errors, output locks.

Every file the toolkit produces goes through :func:`atomic_write` (temporary file in the same folder,
fsync, rename), so a reader never sees half a file under its final name and a failed write leaves no
temporary behind. Write errors (full disk, read-only file system, permissions) become one
:class:`OutputError` line naming the path. :class:`OutputLock` gives one writer per output folder, and
:func:`check_output` applies the CLI convention for existing outputs (``--resume`` / ``--overwrite``).

This module needs only the standard library; gttnet imports it, gttdata never imports gttnet.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import shutil
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from gttdata.errors import OutputError

__all__ = [
    "LOCK_NAME",
    "TRAINING_RUN_MARKERS",
    "OutputLock",
    "atomic_write",
    "check_output",
    "dataset_contents",
    "describe_os_error",
    "die_with_parent",
    "file_sha256",
    "file_size_limit",
    "fsync_dir",
    "remove_output",
    "refuse_foreign_output",
    "reserve_space",
    "trim_reserve",
    "write_bytes_atomic",
    "write_error",
]

#: Name of the advisory lock file :class:`OutputLock` keeps inside an output folder.
LOCK_NAME = ".gtt.lock"

_REASONS = {
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
    errno.EFBIG: "file too large",
    errno.EIO: "input/output error",
}


def file_sha256(path: str | Path, *, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file's bytes, read in ``chunk``-byte pieces."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


def describe_os_error(exc: OSError) -> str:
    """``no space left on device (errno 28)``: the reason of an OS error, without its path."""
    reason = (_REASONS.get(exc.errno) if exc.errno is not None else None) or exc.strerror or str(exc)
    return reason + (f" (errno {exc.errno})" if exc.errno else "")


def write_error(path: str | Path, exc: OSError) -> OutputError:
    """One line for a failed write: ``PATH: cannot write: no space left on device (errno 28)``."""
    return OutputError(f"{path}: cannot write: {describe_os_error(exc)}")


def fsync_dir(path: str | Path) -> None:
    """Make renames inside ``path`` durable (a no-op where directories cannot be opened)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_write(path: str | Path, mode: str = "wb") -> Iterator:
    """Open a temporary file next to ``path``; on success fsync it and rename it to ``path``.

    On any error the temporary file is removed and ``path`` is left as it was; an ``OSError`` becomes
    one :class:`OutputError` line naming ``path``.

    Example::

        with atomic_write("out/model.json", "w") as fh:
            fh.write(text)

    Args:
        path: Final file path (its folder must exist).
        mode: ``"wb"`` or ``"w"`` (text, UTF-8).

    Yields:
        The open temporary file.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, mode, encoding=None if "b" in mode else "utf-8") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise write_error(path, exc) from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    fsync_dir(path.parent)


def write_bytes_atomic(path: str | Path, data: bytes | memoryview) -> None:
    """Write ``data`` to ``path`` through :func:`atomic_write`."""
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def _fallocate():
    """The libc ``fallocate`` (Linux), or None."""
    import ctypes

    try:
        fn = ctypes.CDLL(None, use_errno=True).fallocate
    except (AttributeError, OSError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
    return fn


_FALLOC_FL_KEEP_SIZE = 1


def reserve_space(fd: int, offset: int, length: int, path: str | Path) -> None:
    """Allocate disk blocks for bytes ``[offset, offset + length)`` of an open file, keeping its size.

    Call it before a library that does not survive a failed write (HDF5) writes up to ``length`` bytes
    at ``offset``: a full disk then surfaces here, as one :class:`OutputError` line naming ``path``,
    and the write that follows cannot run out of space. Where ``fallocate`` is unsupported, the free
    space of the file system is checked instead (which another process may still consume).

    Raises:
        OutputError: Not enough space.
    """
    import ctypes

    _check_size_limit(offset + length, path)
    fn = _fallocate()
    if fn is not None and length > 0:
        if fn(fd, _FALLOC_FL_KEEP_SIZE, offset, length) == 0:
            return
        code = ctypes.get_errno()
        if code in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO):
            raise write_error(path, OSError(code, os.strerror(code)))
    st = os.fstatvfs(fd)
    if st.f_bavail * st.f_frsize < length:
        raise write_error(path, OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)))


def file_size_limit() -> int | None:
    """This process's largest writable file size in bytes (``ulimit -f``), or None when unlimited."""
    try:
        import resource
    except ImportError:  # not on POSIX
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY or soft < 0 else int(soft)


def _check_size_limit(end: int, path: str | Path) -> None:
    """Refuse to grow a file past the per-process size limit (EFBIG) before a write meets it.

    ``fallocate`` with ``FALLOC_FL_KEEP_SIZE`` does not apply ``RLIMIT_FSIZE`` (the size does not
    change), so the limit would first surface inside HDF5's writes, which it does not survive.
    """
    limit = file_size_limit()
    if limit is not None and end > limit:
        raise OutputError(
            f"{path}: cannot write: {describe_os_error(OSError(errno.EFBIG, os.strerror(errno.EFBIG)))}: "
            f"the file would reach {end} bytes, over this process's file size limit of {limit} bytes (ulimit -f)"
        )


def trim_reserve(path: str | Path) -> None:
    """Free blocks :func:`reserve_space` allocated beyond the end of a closed file (size unchanged)."""
    size = os.path.getsize(path)
    os.truncate(path, size + 1)  # a shrinking truncate frees everything past the new end
    os.truncate(path, size)


class OutputLock:
    """Advisory lock giving one writer per output folder (``flock`` on ``DIR/.gtt.lock``).

    The lock file holds the holder's PID, so a second writer is refused with one line naming it. The
    kernel releases the lock when the holder exits in any way (``kill -9`` included), so a stale lock
    file never blocks a later run.

    Example::

        with OutputLock(out_dir, "gttdata generate"):
            ...  # write shards

    Args:
        folder: The output folder (created).
        what: The command taking the lock, for the message.
        shared: Take a shared lock: writers of disjoint parts (``--shard-range`` array jobs) may hold
            it together, and they exclude every exclusive holder (a run over the whole folder).
    """

    def __init__(
        self, folder: str | Path, what: str = "another gtt process", *, shared: bool = False
    ) -> None:
        self.folder, self.what, self.shared = Path(folder), what, shared
        self._fd: int | None = None

    def __enter__(self) -> OutputLock:
        import fcntl

        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            path = self.folder / LOCK_NAME
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise write_error(self.folder, exc) from exc
        try:
            fcntl.flock(fd, (fcntl.LOCK_SH if self.shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
        except OSError as exc:
            holder = os.pread(fd, 64, 0).decode(errors="replace").split()
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise write_error(path, exc) from exc
            pid = holder[0] if holder else "unknown"
            name = " ".join(holder[1:]) or "another gtt process"
            raise OutputError(
                f"{self.folder}: in use by {name} (PID {pid}); wait for it to finish or stop it, "
                "then run again (one writer per output folder)"
            ) from None
        os.ftruncate(fd, 0)  # shared holders each record themselves; the last one is named
        os.pwrite(fd, f"{os.getpid()} {self.what}\n".encode(), 0)
        self._fd = fd
        return self

    def __exit__(self, *exc) -> None:
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, 0)
            os.close(self._fd)  # releases the flock
            self._fd = None


def check_output(
    path: str | Path, *, exists: bool, resume: bool, overwrite: bool, what: str, resumable: bool = True
) -> None:
    """The CLI convention for an existing output: refuse unless ``--resume`` or ``--overwrite``.

    Args:
        path: The output (file or folder), for the message.
        exists: Whether it already holds an output.
        resume: ``--resume`` was given (continue it).
        overwrite: ``--overwrite`` was given (replace it).
        what: What the output holds, e.g. ``"a dataset"``.
        resumable: Whether the command has ``--resume`` (the message offers only what exists).

    Raises:
        OutputError: ``exists`` and neither flag, or both flags.
    """
    if resume and overwrite:
        raise OutputError(f"{path}: give --resume (continue) or --overwrite (replace), not both")
    if exists and not (resume or overwrite):
        ways = (
            "pass --resume to continue it or --overwrite to replace it"
            if resumable
            else "pass --overwrite to replace it"
        )
        raise OutputError(f"{path}: already holds {what}; {ways}")


#: Files that only a ``gttnet train`` run writes into its folder (all are in ``gttnet.train.rundir.RUN_FILES``).
TRAINING_RUN_MARKERS = ("checkpoint.pt", "model.pt", "model.json", "log.jsonl", "item_cache")


def dataset_contents(folder: str | Path) -> str | None:
    """What makes ``folder`` a gttdata dataset, in words (``manifest.json and 3 shard files``), or None."""
    folder = Path(folder)
    found = []
    if (folder / "manifest.json").is_file():
        found.append("manifest.json")
    n = sum(1 for _ in folder.glob("*/shard-*.h5")) + sum(1 for _ in folder.glob("*/shard-*.h5.tmp"))
    if n:
        found.append(f"{n} shard file{'s' if n > 1 else ''}")
    return " and ".join(found) or None


def refuse_foreign_output(folder: str | Path, *, writer: str) -> None:
    """Refuse to write a dataset into a training run's folder, or a training run into a dataset's.

    ``gttnet train --out`` and ``gttdata generate --out`` each manage their own files (``--overwrite``
    deletes them); mixing the two in one folder would leave neither intact. Refused whatever the flags.

    Args:
        folder: The output folder.
        writer: ``"gttdata generate"`` (writes a dataset) or ``"gttnet train"`` (writes a training run).

    Raises:
        OutputError: ``folder`` holds the other kind of output, naming what it holds.
        ValueError: Unknown ``writer``.
    """
    folder = Path(folder)
    if not folder.is_dir():
        return
    if writer == "gttdata generate":
        run = [name for name in TRAINING_RUN_MARKERS if (folder / name).exists()]
        if run:
            raise OutputError(
                f"{folder}: holds a gttnet training run ({', '.join(run)}), not a dataset; "
                "write the dataset to another folder (--out)"
            )
    elif writer == "gttnet train":
        data = dataset_contents(folder)
        if data:
            raise OutputError(
                f"{folder}: holds a gttdata dataset ({data}), not a training run; "
                "write the run to another folder (--out)"
            )
    else:
        raise ValueError(f"writer must be 'gttdata generate' or 'gttnet train', got {writer!r}")


def remove_output(paths: list[Path]) -> None:
    """Delete files and folders of an output being replaced (``--overwrite``); missing ones are fine."""
    for p in paths:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)


def die_with_parent(parent: int | None = None, poll_s: float = 0.5) -> None:
    """Make this (worker) process exit when its parent dies, even by ``kill -9``.

    Linux: ``PR_SET_PDEATHSIG`` delivers SIGKILL when the parent goes. Everywhere: a daemon thread
    watches ``os.getppid()`` and exits the process when it changes (the parent was re-parented away).
    Call it first thing in a worker (a pool initializer), with the PID of the process that created
    the pool: a parent killed while the worker was still starting is then noticed too.
    """
    parent = os.getppid() if parent is None else parent
    with contextlib.suppress(Exception):
        import ctypes
        import signal

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    if os.getppid() != parent:  # died before prctl took effect
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()
