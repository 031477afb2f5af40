"""Item 3: a full disk is one line naming the path, leaves no temporary file, and keeps finished shards."""

from __future__ import annotations

import ctypes
import errno
import os

import pytest
from click.testing import CliRunner

import gttdata.fileio as fileio
from gttdata.cli import main
from gttdata.shards.reader import ShardReader
from tests.reliability.conftest import TINY, cli, one_line_error


def _leftovers(root):
    return [p for p in root.rglob("*") if p.name.endswith(".tmp")]


def test_full_tmpfs_generate_is_one_line(small_fs):
    """A real 2 MiB file system filled by the dataset (segfaulted with exit 139 before)."""
    out = small_fs / "d"
    res = cli("gttdata", "generate", TINY, "splits.0.n_samples=60", "--out", str(out), "--no-progress")
    line = one_line_error(res)
    assert "no space left on device" in line and str(out) in line
    assert not _leftovers(out)
    finished = sorted(out.glob("*/shard-*.h5"))
    assert finished, "some blocks fit before the disk filled"
    for p in finished:
        ShardReader(p).check()  # what has a final name is complete


def test_injected_enospc_is_one_line(tmp_path, monkeypatch):
    """The same path without root: the space reservation reports ENOSPC (as a full disk would)."""

    def full(fd, mode, offset, length):
        ctypes.set_errno(errno.ENOSPC)
        return -1

    monkeypatch.setattr(fileio, "_fallocate", lambda: full)
    out = tmp_path / "d"
    line = one_line_error(CliRunner().invoke(main, ["generate", TINY, "--out", str(out), "--no-progress"]))
    assert "no space left on device" in line and "train/shard-00000.h5" in line
    assert not _leftovers(out)


def test_read_only_output_is_one_line(tmp_path):
    if os.geteuid() == 0:
        pytest.skip("root ignores directory permissions; the tmpfs and injected cases cover write errors")
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        res = CliRunner().invoke(main, ["generate", TINY, "--out", str(ro / "d"), "--no-progress"])
    finally:
        ro.chmod(0o700)
    line = one_line_error(res)
    assert str(ro / "d") in line
