"""The README's examples run as written and print what the README says (keeps the documentation true).

Every command of every ``bash`` block (except the two set-up commands) must have an entry in ``CHECKS``: how
to run it on tiny data in the default suite (or None: slow only) and what its output must show. The default
run executes the cheap commands, in README order, in one temporary folder on the tiny recipe's dataset
standing in for ``data/gttdata/default``; ``pytest -m slow`` runs every command exactly as written, in order,
in a fresh folder (14 min on 2 shared cores, 5 of them the σ = 4 px paper dataset; the CMU fetch needs apt).
The ``python`` blocks run in the same folder as the cheap commands, so the one that loads
``data/gttdata/default`` finds it.
"""

from __future__ import annotations

import json
import os
import re
import shlex
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
TEXT = README.read_text()
PY_BLOCKS = re.findall(r"```python\n(.*?)```", TEXT, re.S)
SETUP = ("make demo", "make test")


def readme_commands() -> list[str]:
    """Every shell command of the README's bash blocks, comments stripped, in order (set-up block excluded)."""
    out = []
    for block in re.findall(r"```bash\n(.*?)```", TEXT, re.S):
        for line in block.replace("\\\n", " ").splitlines():
            argv = shlex.split(line, comments=True)
            if argv and " ".join(argv[:2]) not in SETUP:
                out.append(shlex.join(argv))
    return out


def _json(out: str) -> dict:
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert len(lines) == 1, out
    return json.loads(lines[0])


def _check_reconstruct_gttnet(out: str) -> None:
    d = _json(out)
    assert d["method"] == "gttnet" and d["sequencing"] == "none" and d["n_joints"] == 31
    assert 0 < d["mpjpe_mm"] < 150 and -1 <= d["order_kendall_tau"] <= 1, d


def _check_reconstruct_dloe(out: str) -> None:
    assert re.search(r"method=dloe sequencing=partial .*mpjpe_mm=\d", out) and "-> runs/rec.h5" in out, out
    assert Path("runs/rec.h5").is_file()


def _check_reconstruct_json(out: str) -> None:
    """The exported JSON gives the shard's own answer: its recorded unit is read back, nothing guessed."""
    d = _json(out)
    assert d["method"] == "dloe" and d["sequencing"] == "partial" and d["n_joints"] == 31, d
    shard = _json(
        _invoke(
            shlex.split(
                "gttnet reconstruct data/gttdata/default/test/shard-00000.h5 --sample 0 --method dloe "
                "--sequencing partial --json"
            )
        )
    )
    assert d["mpjpe_mm"] == pytest.approx(shard["mpjpe_mm"], abs=0.05), (d, shard)


def _check_segment(out: str) -> None:
    ari = float(re.search(r"\bari=(\S+)", out).group(1))
    assert "n_events=2" in out and ari == pytest.approx(1.0), out  # the README's claim for sample 1
    assert {p.name for p in Path("runs/segment").iterdir()} >= {
        "labels.csv",
        "segmentation.json",
        "affinity.png",
    }


def _check_subjects(out: str) -> None:
    d = _json(out)
    assert d["n_subjects"] == 2 and d["sequencing"] == "none" and d["clustering_accuracy"] >= 0.9, d
    assert len(d["mpjpe_mm_per_subject"]) == 2


def _check_sync(out: str) -> None:
    assert "-> runs/clocks.json" in out and "offset std ms" in out, out
    assert re.search(
        r"offset error vs the file's true times, frames: ([+-]0\.[0-2]\d*(, )?){3}$", out, re.M
    ), out
    assert json.loads(Path("runs/clocks.json").read_text())["format"] == "gtt-clocks/1"


def _check_reconstruct_auto_sync(out: str) -> None:
    d = _json(out)
    assert d["method"] == "sync" and d["requested_method"] == "auto" and len(d["clock_offsets_s"]) == 3, d
    assert 0 < d["mpjpe_mm"] < 50 and d["order_kendall_tau"] > 0.9, d


def _check_inspect(out: str) -> None:
    assert re.search(r"^dataset\s+\S+", out, re.M) and re.search(r"^total\s+\d+\s+\d+", out, re.M), out
    assert "{" not in out and "PosixPath" not in out


def _tiny_generate(argv: list[str]) -> list[str]:
    """``generate default.yaml ...`` -> the tiny recipe written where the default dataset goes."""
    return [
        "gttdata",
        "generate",
        "recipes/gttdata/tiny.yaml",
        "--out",
        "data/gttdata/default",
        "--no-progress",
    ]


Check = tuple[Callable[[list[str]], list[str]] | None, Callable[[str], None]]

#: Command prefix -> (tiny rewrite for the default suite, or None for slow only; output check).
CHECKS: dict[str, Check] = {
    "gttdata motions fetch": (None, lambda out: re.search(r"\d+ motion files in", out) or pytest.fail(out)),
    "gttdata motions show 01_01.bvh": (
        None,
        lambda out: re.search(r"^frames: \d+", out, re.M) or pytest.fail(out),
    ),
    "gttdata generate recipes/gttdata/default.yaml": (
        _tiny_generate,
        lambda out: re.search(r"manifest \S+manifest.json verified", out) or pytest.fail(out),
    ),
    "gttdata generate recipes/gttdata/paper.yaml capture.sigma_px=4": (
        None,
        lambda out: ("paper_sigma4" in out and "verified" in out) or pytest.fail(out),
    ),
    "gttdata verify data/gttdata/default": (
        lambda a: a,
        lambda out: re.search(r"OK \(\d+ shards, \d+ samples\)", out) or pytest.fail(out),
    ),
    "gttdata inspect data/gttdata/default": (lambda a: a, _check_inspect),
    "gttdata preview data/gttdata/default": (
        None,
        lambda out: (re.search(r"_contact\.png$", out, re.M) and ".mp4" in out) or pytest.fail(out),
    ),
    "gttnet reconstruct data/gttdata/default/test/shard-00000.h5 --sample 0 --method gttnet": (
        lambda a: a,
        _check_reconstruct_gttnet,
    ),
    "gttnet reconstruct data/gttdata/default/test/shard-00000.h5 --sample 1 --method dloe": (
        lambda a: a,
        _check_reconstruct_dloe,
    ),
    "gttnet train recipes/gttnet/tiny.yaml": (
        None,
        lambda out: (
            re.search(r"run runs/tiny: finished.*model: runs/tiny/model.pt", out, re.S) or pytest.fail(out)
        ),
    ),
    "gttnet evaluate recipes/gttnet/eval_smoke.yaml": (
        None,
        lambda out: ("evaluation -> runs/eval_smoke" in out and "| dloe" in out) or pytest.fail(out),
    ),
    "gttnet segment recipes/gttdata/events.yaml --sample 1": (None, _check_segment),
    "gttdata generate recipes/gttdata/multi_subject.yaml": (
        None,
        lambda out: "verified" in out or pytest.fail(out),
    ),
    "gttnet reconstruct data/gttdata/multi_subject/test/shard-00000.h5 --subjects 2": (None, _check_subjects),
    "gttnet export-json data/gttdata/default": (
        lambda a: a,
        lambda out: (
            "runs/capture.json: " in out and out.rstrip().endswith("lengths in m") or pytest.fail(out)
        ),
    ),
    "gttnet reconstruct runs/capture.json": (lambda a: a, _check_reconstruct_json),
    "gttdata generate recipes/gttdata/tiny.yaml --resume": (
        lambda a: [*a, "--no-progress"],
        lambda out: "data/gttdata/tiny/manifest.json verified" in out or pytest.fail(out),
    ),
    "gttdata export data/gttdata/tiny": (
        lambda a: a,
        lambda out: "-> runs/recording/project.toml" in out or pytest.fail(out),
    ),
    "ls runs/recording": (
        lambda a: a,
        lambda out: (
            {"cam_0", "calibration.toml", "project.toml", "ground_truth.npz"} <= set(out.split())
            or pytest.fail(out)
        ),
    ),
    "gttnet reconstruct runs/recording/project.toml": (
        None,
        lambda out: 0 < _json(out)["mpjpe_mm"] < 150 or pytest.fail(out),
    ),
    "gttnet reconstruct --calibration runs/recording/calibration.toml": (
        None,
        lambda out: "-> runs/recording/result.csv" in out or pytest.fail(out),
    ),
    "gttnet sync data/gttdata/tiny/test/shard-00000.h5": (lambda a: a, _check_sync),
    "gttnet reconstruct data/gttdata/tiny/test/shard-00000.h5 --sequencing partial": (
        lambda a: a,
        _check_reconstruct_auto_sync,
    ),
    "gttnet render runs/recording/result.h5": (
        None,
        lambda out: re.search(r"reprojection error [\d.]+ px .*cam_0\.mp4", out) or pytest.fail(out),
    ),
}


def _entry(command: str) -> Check:
    keys = [k for k in CHECKS if command.startswith(k)]
    assert keys, f"README command has no check in tests/test_readme.py: {command}"
    return CHECKS[max(keys, key=len)]


def _invoke(argv: list[str]) -> str:
    from gttdata.cli import main as gttdata_main
    from gttnet.cli import main as gttnet_main

    if argv[0] == "ls":  # the README lists a folder the previous example wrote
        return "\n".join(sorted(os.listdir(argv[1])))
    mains = {"gttdata": gttdata_main, "gttnet": gttnet_main}
    assert argv[0] in mains, f"README: unexpected program {argv[0]!r}"
    res = CliRunner().invoke(mains[argv[0]], argv[1:], catch_exceptions=False)
    assert res.exit_code == 0, f"{shlex.join(argv)} exited {res.exit_code}:\n{res.output}"
    return res.stdout


def _folder(tmp: Path) -> Path:
    (tmp / "recipes").symlink_to(ROOT / "recipes")
    return tmp


def test_every_readme_command_has_a_check():
    commands = readme_commands()
    assert len(commands) >= 10
    for c in commands:
        _entry(c)


@pytest.fixture(scope="module")
def tiny_readme(tmp_path_factory) -> Path:
    """A folder where the README's cheap commands ran, in order, on tiny data (checked as they run)."""
    tmp = _folder(tmp_path_factory.mktemp("readme"))
    cwd = Path.cwd()
    os.chdir(tmp)
    try:
        for command in readme_commands():
            rewrite, check = _entry(command)
            if rewrite is not None:
                check(_invoke(rewrite(shlex.split(command))))
    finally:
        os.chdir(cwd)
    return tmp


def test_readme_commands_on_tiny_data(tiny_readme):
    assert (tiny_readme / "data/gttdata/default/manifest.json").is_file()


@pytest.mark.slow
def test_readme_commands_as_written(tmp_path, monkeypatch):
    """Every README command exactly as written, in order (833 s on 2 shared cores)."""
    monkeypatch.chdir(_folder(tmp_path))
    monkeypatch.setenv("GTT_CACHE", str(tmp_path / "cache"))
    for command in readme_commands():
        _entry(command)[1](_invoke(shlex.split(command)))


def test_readme_has_examples():
    assert len(PY_BLOCKS) >= 3


@pytest.mark.parametrize("code", PY_BLOCKS, ids=[f"block{i}" for i in range(len(PY_BLOCKS))])
def test_readme_example_runs(code, tiny_readme, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tiny_readme if "data/gttdata/" in code else tmp_path)
    exec(compile(code.replace("/tmp/rig.toml", str(tmp_path / "rig.toml")), str(README), "exec"), {})
    out = capsys.readouterr().out
    assert "False" not in out
    # Each top-level `print(...)  # comment` line: what it prints is written in its comment.
    comments = re.findall(r"^print\(.*#\s*(.+)$", code, re.M)
    lines = [ln.strip() for ln in out.splitlines()]
    assert len(lines) == len(comments), out
    for printed, comment in zip(lines, comments, strict=True):
        assert printed in comment, f"README says {comment!r}, the code prints {printed!r}"
