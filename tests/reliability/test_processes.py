"""Item 5 and the kill tests: two real writers on one folder, orphan workers, ``kill -9`` then resume."""

from __future__ import annotations

import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gttdata.shards.reader import ShardReader
from tests._subprocess import repo_env
from tests.reliability.conftest import REPO, TINY, cli, one_line_error


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "gttdata", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=repo_env(),
        cwd=REPO,
    )


def _wait_for(cond, timeout: float = 60.0, what: str = "condition") -> None:
    t0 = time.monotonic()
    while not cond():
        if time.monotonic() - t0 > timeout:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


def _holder(out: Path) -> str:
    lock = out / ".gtt.lock"
    return lock.read_text().split()[0] if lock.exists() and lock.read_text().strip() else ""


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.glob("*/*.h5*"))}


def _descendants(pid: int) -> set[int]:
    """PIDs of all processes below ``pid`` (Linux /proc)."""
    kids: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                ppid = int((d / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            kids.setdefault(ppid, []).append(int(d.name))
    out, todo = set(), [pid]
    while todo:
        for k in kids.get(todo.pop(), []):
            out.add(k)
            todo.append(k)
    return out


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_second_writer_is_refused_naming_the_holder(tmp_path):
    """Two real processes on one folder; it was two HDF5 locking errors, or a mixed folder."""
    import json

    out = tmp_path / "d"
    first = _start("generate", TINY, "splits.0.n_samples=400", "--out", str(out), "--no-progress")
    _wait_for(lambda: _holder(out) == str(first.pid), what="the first writer's lock")
    second = cli("gttdata", "generate", TINY, "seed=9", "--out", str(out), "--no-progress")
    still_running = first.poll() is None
    line = one_line_error(second)
    assert still_running, "the first run ended before the second started; give it more work"
    assert f"PID {first.pid}" in line and str(out) in line
    first.kill()
    first.wait()
    hashes = set()
    for p in out.glob("*/shard-*.h5"):
        with ShardReader(p) as r:
            hashes.add(
                json.loads(r.attrs["recipe"])["seed"]
                if isinstance(r.attrs["recipe"], str)
                else r.attrs["recipe"]["seed"]
            )
    assert hashes <= {7}, "the refused writer wrote nothing"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc to find the workers")
def test_workers_die_with_their_parent(tmp_path):
    """Reproduction: ``kill -9`` of the parent of a ``--workers 2`` run left its workers running."""
    out = tmp_path / "d"
    proc = _start(
        "generate", TINY, "splits.0.n_samples=400", "--out", str(out), "--workers", "2", "--no-progress"
    )
    # both workers are past their start-up once each writes a block (two .tmp files, or more shards)
    _wait_for(
        lambda: len(list(out.glob("train/*.h5*"))) >= 3 or proc.poll() is not None,
        timeout=120,
        what="the workers",
    )
    workers = _descendants(proc.pid)
    assert proc.poll() is None and workers, "the run ended before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    _wait_for(lambda: not any(_alive(w) for w in workers), timeout=30, what="the orphan workers to exit")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kill_9_at_a_random_point_then_resume_is_bit_identical(tmp_path, tiny_data, seed):
    """A real ``kill -9`` at a seeded random point, then ``--resume``: an uninterrupted run's bytes.

    The resumed dataset also passes ``verify --deep``.
    """
    from click.testing import CliRunner

    from gttdata.cli import main

    out = tmp_path / "d"
    proc = _start("generate", TINY, "--out", str(out), "--no-progress")
    _wait_for(lambda: _holder(out) == str(proc.pid) or proc.poll() is not None, what="the writer to start")
    time.sleep(random.Random(seed).uniform(0.0, 0.4))  # the tiny recipe writes for ~0.3 s
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(out), "--resume", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert _files(out) == _files(tiny_data)
    assert CliRunner().invoke(main, ["verify", str(out), "--deep"]).exit_code == 0
