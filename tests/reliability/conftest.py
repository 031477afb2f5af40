"""Fault injection: helpers shared by the reliability tests (real processes, one-line errors, tmpfs)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from tests._subprocess import repo_env

REPO = Path(__file__).resolve().parents[2]
TINY = str(REPO / "recipes/gttdata/tiny.yaml")  # 8 samples in 3 blocks; generates in ~0.3 s


def cli(package: str, *args: str, timeout: float = 120, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m <package> ARGS`` as a real process (a segfault shows as a negative return code)."""
    return subprocess.run(
        [sys.executable, "-m", package, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=repo_env(),
        cwd=kw.pop("cwd", REPO),
        **kw,
    )


def one_line_error(result) -> str:
    """Assert the ONE-line failure contract: non-zero exit, one ``Error:`` line, no traceback, no crash.

    Works for both ``subprocess.CompletedProcess`` and click's ``CliRunner`` results.
    """
    code = getattr(result, "returncode", getattr(result, "exit_code", None))
    text = (getattr(result, "stdout", "") or "") + (getattr(result, "stderr", "") or "")
    if hasattr(result, "exit_code"):
        text = result.output
    assert code not in (0, None), f"expected a failure, got exit 0:\n{text}"
    assert code > 0, f"the process crashed (signal {-code}):\n{text}"
    assert "Traceback" not in text and "Aborted!" not in text, text
    lines = [ln for ln in text.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1, text
    return lines[0]


def flip_byte(path: Path, offset: int | None = None) -> None:
    """Flip one bit of ``path`` at ``offset`` (default: the middle)."""
    data = bytearray(path.read_bytes())
    i = len(data) // 2 if offset is None else offset
    data[i] ^= 0x10
    path.write_bytes(bytes(data))


@pytest.fixture
def small_fs(tmp_path):
    """A 2 MiB tmpfs (root only); the test is skipped with the reason where mounting is not permitted."""
    if shutil.which("mount") is None or not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("cannot mount a tmpfs here: needs root and mount(8)")
    mnt = tmp_path / f"tmpfs-{uuid.uuid4().hex[:6]}"
    mnt.mkdir()
    res = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)], capture_output=True, text=True
    )
    if res.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {res.stderr.strip() or res.returncode}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory) -> Path:
    """The tiny dataset, generated once (read-only for tests: copy it before damaging it)."""
    from click.testing import CliRunner

    from gttdata.cli import main

    out = tmp_path_factory.mktemp("tiny") / "data"
    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(out), "--no-progress"])
    assert res.exit_code == 0, res.output
    return out
