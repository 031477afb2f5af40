"""``--threads`` / ``GTT_THREADS``: every compute command honours the budget; a bad value is one line.

In this (pytest) process numpy and torch are loaded before a command runs, so these tests see what
threadpoolctl reports after the command; ``test_threads_in_a_fresh_process`` checks the other path, where
the pools start after the option has set their environment variables.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from click.testing import CliRunner
from threadpoolctl import threadpool_info, threadpool_limits

from gttdata import threads as gtt_threads
from gttdata.cli import main as gttdata_main
from gttnet.cli import main as gttnet_main
from tests._subprocess import repo_env

TINY = "recipes/gttdata/tiny.yaml"
SAVED_VARS = (*gtt_threads.THREAD_ENV_VARS, gtt_threads.ENV_VAR)


@pytest.fixture(autouse=True)
def restore_threads(monkeypatch):
    """Put back the environment, the BLAS/OpenMP limits and torch's thread count a command changed."""
    import torch

    for var in SAVED_VARS:  # monkeypatch restores each variable (set or unset) at teardown
        if var in os.environ:
            monkeypatch.setenv(var, os.environ[var])
        else:
            monkeypatch.delenv(var, raising=False)
    original = threadpool_limits(limits=None)  # records every pool's current size, changes nothing
    n_torch = torch.get_num_threads()
    yield
    original.restore_original_limits()
    torch.set_num_threads(n_torch)


@pytest.fixture(scope="module")
def shard(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny")
    res = CliRunner().invoke(gttdata_main, ["generate", TINY, "--out", str(out), "--no-progress"])
    assert res.exit_code == 0, res.output
    return str(out / "test" / "shard-00000.h5")


def _sync(shard: str, tmp_path) -> list[str]:
    return ["sync", shard, "--out", str(tmp_path / "clocks.json"), "--overwrite"]


def _pool_sizes() -> set[int]:
    return {lib["num_threads"] for lib in threadpool_info()}


def _set_everything(n: int) -> None:
    import torch

    threadpool_limits(limits=n)
    torch.set_num_threads(n)


@pytest.mark.parametrize(
    "command",
    [
        ["reconstruct", "{shard}", "--method", "pseudo", "--json"],
        ["sync", "{shard}", "--out", "{tmp}/clocks.json", "--overwrite"],
    ],
    ids=["reconstruct", "sync"],
)
@pytest.mark.parametrize("how", ["option", "env"])
def test_threads_one_is_honoured(shard, command, how, tmp_path):
    import torch

    if not threadpool_info():
        pytest.skip("threadpoolctl sees no BLAS/OpenMP pool in this process")
    _set_everything(3)
    argv = [a.format(shard=shard, tmp=tmp_path) for a in command]
    args, env = ([*argv, "--threads", "1"], {}) if how == "option" else (argv, {"GTT_THREADS": "1"})
    res = CliRunner().invoke(gttnet_main, args, env=env)
    assert res.exit_code == 0, res.output
    assert _pool_sizes() == {1}, threadpool_info()
    assert torch.get_num_threads() == 1
    assert os.environ["OMP_NUM_THREADS"] == os.environ["OPENBLAS_NUM_THREADS"] == "1"
    assert gtt_threads.requested_threads() == 1


def test_option_wins_over_environment(shard, tmp_path):
    _set_everything(3)
    res = CliRunner().invoke(
        gttnet_main,
        [*_sync(shard, tmp_path), "--threads", "2"],
        env={"GTT_THREADS": "1", "OMP_NUM_THREADS": "7"},
    )
    assert res.exit_code == 0, res.output
    assert gtt_threads.requested_threads() == 2 and _pool_sizes() == {2}


def test_default_is_capped_and_keeps_the_users_settings(shard, monkeypatch, tmp_path):
    monkeypatch.delenv("GTT_THREADS", raising=False)
    for var in gtt_threads.THREAD_ENV_VARS:
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setattr(gtt_threads, "usable_cores", lambda: 64)
    monkeypatch.setattr(os, "getloadavg", lambda: (0.2, 0.2, 0.2))
    _set_everything(5)
    res = CliRunner().invoke(gttnet_main, _sync(shard, tmp_path))
    assert res.exit_code == 0, res.output
    assert gtt_threads.requested_threads() is None
    assert os.environ["OMP_NUM_THREADS"] == "4" and _pool_sizes() <= {4}  # min(64 cores, 4)
    # A user's own OMP_NUM_THREADS is theirs: the default changes nothing then.
    _set_everything(3)
    res = CliRunner().invoke(gttnet_main, _sync(shard, tmp_path), env={"OMP_NUM_THREADS": "3"})
    assert res.exit_code == 0, res.output
    assert _pool_sizes() == {3}  # the default (4 here) was not applied


@pytest.mark.parametrize("value", ["0", "-1", "x", "1.5", ""])
@pytest.mark.parametrize(
    "main,command",
    [
        (gttnet_main, ["reconstruct", "{shard}"]),
        (gttnet_main, ["sync", "{shard}"]),
        (gttnet_main, ["evaluate", "recipes/gttnet/eval_smoke.yaml"]),
        (gttnet_main, ["train", "recipes/gttnet/tiny.yaml"]),
        (gttnet_main, ["segment", "recipes/gttdata/events.yaml"]),
        (gttnet_main, ["render", "{shard}"]),
        (gttdata_main, ["generate", TINY]),
        (gttdata_main, ["preview", "{shard}"]),
        (gttdata_main, ["export", "{shard}"]),
    ],
    ids=lambda x: x[0] if isinstance(x, list) else "",
)
def test_bad_value_is_one_line(shard, main, command, value):
    """The option is checked before the command runs: one line naming the source, expected and found."""
    argv = [a.format(shard=shard) for a in command]
    for args, env, source in (
        ([*argv, "--threads", value], {}, "--threads"),
        (argv, {"GTT_THREADS": value}, "GTT_THREADS"),
    ):
        res = CliRunner().invoke(main, args, env=env)
        assert res.exit_code == 1, res.output
        assert "Traceback" not in res.output and len(res.output.strip().splitlines()) == 1, res.output
        assert res.output.startswith(
            f"Error: {source}: expected a whole number of threads >= 1, got '{value}'"
        )


@pytest.mark.parametrize(
    ("cores", "load", "expected"),
    [(2, 0.1, 2), (2, 0.7, 1), (2, 13.0, 1), (16, 0.0, 4), (16, 13.4, 3), (1, 0, 1)],
)
def test_default_leaves_busy_cores_alone(monkeypatch, cores, load, expected):
    monkeypatch.setattr(gtt_threads, "usable_cores", lambda: cores)
    monkeypatch.setattr(os, "getloadavg", lambda: (load, load, load))
    assert gtt_threads.default_threads() == expected


def test_worker_threads(monkeypatch):
    """A worker runs one thread unless the command was given a count, which each worker then uses."""
    monkeypatch.delenv("GTT_THREADS", raising=False)
    gtt_threads.limit_worker_threads()
    assert os.environ["OMP_NUM_THREADS"] == "1"
    monkeypatch.setenv("GTT_THREADS", "2")
    gtt_threads.limit_worker_threads()
    assert os.environ["OMP_NUM_THREADS"] == "2"


def test_threads_in_a_fresh_process(shard):
    """In a real command the pools start after --threads set their variables: numpy and torch start at 1."""
    code = (
        "import json, sys\n"
        "from gttnet.cli import main\n"
        "try:\n"
        "    main(sys.argv[1:], standalone_mode=False)\n"
        "finally:\n"
        "    from threadpoolctl import threadpool_info\n"
        "    torch = sys.modules.get('torch')\n"
        "    print(json.dumps({'pools': [p['num_threads'] for p in threadpool_info()],\n"
        "        'torch': torch.get_num_threads() if torch else None}))\n"
    )
    env = {k: v for k, v in repo_env().items() if k not in SAVED_VARS}
    res = subprocess.run(
        [sys.executable, "-c", code, "reconstruct", shard, "--method", "dloe", "--json", "--threads", "1"],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    found = json.loads(res.stdout.strip().splitlines()[-1])
    assert found["pools"] and set(found["pools"]) == {1}, found
    assert found["torch"] in (None, 1), found
