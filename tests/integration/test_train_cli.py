"""``gttnet train`` end to end on the tiny recipe through the CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from gttnet.cli import main

REPO = Path(__file__).resolve().parents[2]
TINY = str(REPO / "recipes" / "gttnet" / "tiny.yaml")
pytestmark = pytest.mark.integration


@pytest.fixture
def in_repo(monkeypatch):
    monkeypatch.chdir(REPO)  # recipes name data recipes relative to the repository root


def test_train_tiny_then_resume_is_a_no_op(tmp_path, in_repo):
    run = tmp_path / "run"
    res = CliRunner().invoke(main, ["train", TINY, "stages.0.steps=2", "stages.1.steps=2", "--out", str(run),
                                    "--device", "cpu", "--quiet"])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "finished" in res.output and "MPJPE" in res.output
    records = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    train = [r for r in records if r["kind"] == "train"]
    assert [r["global_step"] for r in train] == [1, 2, 3, 4]
    assert all(math.isfinite(r["loss"]) for r in records if "loss" in r)
    assert {"loss_structure", "loss_affinity", "loss_autoencoding"} <= set(train[-1])
    for f in ("model.pt", "model.json", "loss_curve.png", "checkpoint.pt", "recipe.yaml"):
        assert (run / f).is_file(), f
    again = CliRunner().invoke(main, ["train", "--out", str(run), "--resume", "--json"])
    assert again.exit_code == 0, again.output
    report = json.loads(again.stdout)  # one JSON object, nothing else on stdout
    assert report["run_dir"] == str(run) and report["finished"] and report["global_step"] == 4
    assert report["model"] == str(run / "model.pt") and math.isfinite(report["val_mpjpe_mm"])
    assert "warning" not in again.output  # the saved recipe names output_dir, not the old out_dir


def test_train_stop_and_resume(tmp_path, in_repo):
    run = tmp_path / "run"
    res = CliRunner().invoke(main, ["train", TINY, "--out", str(run), "--max-steps", "2", "--quiet"])
    assert res.exit_code == 0, res.output
    assert "stopped at step 2" in res.output
    assert f"gttnet train --out {run} --resume" in res.output  # the line says how to continue
    res = CliRunner().invoke(main, ["train", TINY, "--out", str(run), "--resume", "--quiet"])
    assert res.exit_code == 0 and "finished" in res.output, res.output


def test_old_resume_folder_form_still_works_with_a_warning(tmp_path, in_repo):
    """``--resume RUN_DIR`` (before --resume became a flag) is read as ``--out RUN_DIR --resume``."""
    run = tmp_path / "run"
    run.mkdir()  # no checkpoint: the form is read as --out RUN --resume, which then names what is missing
    res = CliRunner().invoke(main, ["train", "--resume", str(run), "--quiet"])
    assert res.exit_code == 1 and "Traceback" not in res.output
    warning, error = res.output.splitlines()
    assert (
        warning
        == f"warning: gttnet train --resume {run} is deprecated; use: gttnet train --out {run} --resume"
    )
    assert error == f"Error: {run / 'checkpoint.pt'}: no checkpoint to resume from"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["train", TINY, "trian.steps=1"], "trian: unknown key"),
        (["train", TINY, "stages.0.steps=zero"], "stages.0.steps: expected an integer"),
        (["train", TINY, "model.builder=gttnet_huge"], "unknown model builder"),
        (["train", "--resume", "/nonexistent/run"], "no checkpoint to resume from"),
        (["train", "--out", "/nonexistent/run", "--resume"], "no checkpoint to resume from"),
        (
            ["train", TINY, "--resume", "/some/run"],
            "--resume takes no folder, use: gttnet train [RECIPE] --out",
        ),
        (["train", "/some/run"], "expected a recipe file (.yaml); to continue a run: gttnet train"),
        (["train"], "give a RECIPE"),
    ],
)
def test_train_errors_are_one_line(args, message, in_repo, tmp_path):
    res = CliRunner().invoke(main, [*args, "--out", str(tmp_path / "run")] if args[1:2] == [TINY] else args)
    assert res.exit_code != 0
    assert message in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "run").exists()  # a bad recipe creates no run directory
