"""Items D3 and D17 of issue 29: a per-file size limit during ``generate``, a failed write during ``export``.

D3: under ``ulimit -f`` HDF5's writes failed with EFBIG (``fallocate`` with ``KEEP_SIZE`` does not apply
the limit), h5py printed tracebacks, the process died with 139 and left a ``.tmp``. D17: ``gttdata export``
on a full disk left half an export under its final name.
"""

from __future__ import annotations

import errno
import resource

import numpy as np
from click.testing import CliRunner

from gttdata.cli import main
from tests.reliability.conftest import TINY, cli, one_line_error


def _limit(n_bytes: int):
    """``preexec_fn`` giving the child process a file size limit of ``n_bytes`` (``ulimit -f``)."""

    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))

    return apply


def _leftovers(root):
    return [p for p in root.rglob("*") if p.name.endswith((".tmp", ".old"))]


def test_file_size_limit_during_generate_is_one_line(tmp_path):
    """``ulimit -f 100``: one line naming the shard and the limit, no ``.tmp``, no crash (139 before)."""
    out = tmp_path / "d"
    res = cli("gttdata", "generate", TINY, "--out", str(out), "--no-progress", preexec_fn=_limit(100 * 1024))
    line = one_line_error(res)  # also: exit > 0, so no signal (SIGXFSZ or SIGSEGV) ended it
    assert "train/shard-00000.h5" in line and "file too large (errno 27)" in line and "102400" in line
    assert "Traceback" not in res.stderr
    assert not _leftovers(out) and not list(out.glob("*/shard-*.h5"))


def test_file_size_limit_with_workers_is_one_line(tmp_path):
    """The same from a spawned worker (it inherits the limit)."""
    out = tmp_path / "d"
    res = cli(
        "gttdata",
        "generate",
        TINY,
        "--out",
        str(out),
        "--no-progress",
        "-j",
        "2",
        preexec_fn=_limit(100 * 1024),
    )
    line = one_line_error(res)
    assert "shard-00000.h5" in line and "file too large" in line
    assert not _leftovers(out)


def _export(src, out, *extra):
    return ["export", str(src), "--split", "test", "--out", str(out), *extra]


def test_export_under_a_file_size_limit_leaves_nothing(tiny_data, tmp_path):
    """A real failed write (EFBIG on ``ground_truth.npz``, 8 KiB) after the detector files were written."""
    out = tmp_path / "rec"
    res = cli("gttdata", *_export(tiny_data, out), preexec_fn=_limit(4096))
    line = one_line_error(res)
    assert str(out) in line and "file too large (errno 27)" in line
    assert not out.exists() and not _leftovers(tmp_path)


def test_export_on_a_full_disk_is_one_line_and_keeps_the_old_export(tiny_data, tmp_path, monkeypatch):
    out = tmp_path / "rec"
    assert CliRunner().invoke(main, _export(tiny_data, out)).exit_code == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", full)  # the last-but-one file of the export
    line = one_line_error(CliRunner().invoke(main, _export(tiny_data, out, "--overwrite")))
    assert str(out) in line and "no space left on device (errno 28)" in line
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before, "the earlier export is kept whole"
    assert not _leftovers(tmp_path) and sorted(p.name for p in tmp_path.iterdir()) == ["rec"]

    fresh = tmp_path / "fresh"
    line = one_line_error(CliRunner().invoke(main, _export(tiny_data, fresh)))
    assert str(fresh) in line and not fresh.exists()


def test_export_into_a_folder_with_other_files_keeps_them_and_never_mixes(tiny_data, tmp_path):
    """``--overwrite`` into a folder that also holds the user's files: those stay; a name clash is one line."""
    out = tmp_path / "rec"
    assert CliRunner().invoke(main, _export(tiny_data, out)).exit_code == 0
    (out / "notes.txt").write_text("mine")
    assert CliRunner().invoke(main, _export(tiny_data, out, "--overwrite")).exit_code == 0
    assert (out / "notes.txt").read_text() == "mine" and (out / "project.toml").is_file()
    (out / "cam_0").rename(tmp_path / "cam_0_moved")  # the earlier export no longer lists ...
    (out / "cam_0").mkdir()
    (out / "cam_0" / "mine.txt").write_text("mine")  # ... a folder of the user's with its name
    res = CliRunner().invoke(main, _export(tiny_data, out, "--overwrite"))
    line = one_line_error(res)
    assert str(out) in line and "cam_0" in line
    assert (out / "cam_0" / "mine.txt").read_text() == "mine" and (out / "notes.txt").read_text() == "mine"
    assert not _leftovers(tmp_path)
