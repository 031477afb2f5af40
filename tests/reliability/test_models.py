"""Items 2 and 4: model and checkpoint files are checked before use; a run is never overwritten silently."""

from __future__ import annotations

import json

import pytest
import torch
from click.testing import CliRunner

from gttnet.cli import main
from gttnet.errors import ModelError
from gttnet.model import inference
from gttnet.model.network import build_model
from gttnet.train.checkpoint import LoopState, load_checkpoint, save_checkpoint
from tests.reliability.conftest import flip_byte, one_line_error


def _model():
    torch.manual_seed(0)
    return build_model("gttnet_tiny", n_joints=5, k=6)


@pytest.fixture
def run_dir(tmp_path):
    """A run directory with a real checkpoint (tiny model, Adam state, RNG states)."""
    model = _model()
    opt = torch.optim.Adam(model.parameters())
    save_checkpoint(
        tmp_path, model=model, optimizer=opt, state=LoopState(global_step=3), recipe={"name": "x"}
    )
    return tmp_path


@pytest.mark.parametrize("name", ["BUNDLED_MODEL", "BUNDLED_POINTNET_MODEL"])
def test_bundled_model_card_holds_its_checksum(name):
    path = getattr(inference, name)
    card = json.loads(path.with_suffix(".json").read_text())
    assert len(card["sha256"]) == 64  # "file" may name the run's model.pt it was copied from
    config = inference.load_model(path).config  # checks size and sha256 against the card
    assert config.n_joints == card["config"]["n_joints"] and config.pointnet == card["config"]["pointnet"]


def test_bitflipped_model_is_refused(tmp_path):
    path = inference.save_model(tmp_path / "m.pt", _model(), card={"note": "t"})
    inference.load_model(path)  # intact: loads
    flip_byte(path)
    with pytest.raises(ModelError, match=r"m.pt: sha256: expected .* found"):
        inference.load_model(path)


def test_bitflipped_model_on_the_cli_is_one_line(tmp_path, tiny_data):
    torch.manual_seed(0)
    path = inference.save_model(tmp_path / "m.pt", build_model("gttnet_tiny"))
    flip_byte(path)
    shard = str(tiny_data / "test/shard-00000.h5")
    line = one_line_error(
        CliRunner().invoke(main, ["reconstruct", shard, "--method", "gttnet", "--model", str(path)])
    )
    assert "m.pt" in line and ("sha256" in line or "expected" in line)


def test_model_without_card_is_refused(tmp_path):
    path = inference.save_model(tmp_path / "m.pt", _model())
    path.with_suffix(".json").unlink()
    with pytest.raises(ModelError, match="model card m.json"):
        inference.load_model(path)


def test_checkpoint_round_trip(run_dir):
    assert load_checkpoint(run_dir)["state"].global_step == 3


@pytest.mark.parametrize("damage", ["bitflip", "empty", "truncated", "garbage"])
def test_damaged_checkpoint_never_resumes(run_dir, damage):
    path = run_dir / "checkpoint.pt"
    if damage == "bitflip":
        flip_byte(path, path.stat().st_size - 200)
    elif damage == "empty":
        path.write_bytes(b"")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    else:
        path.write_bytes(b"\x80\x04garbage that is not a pickle" * 10)
    with pytest.raises(ModelError, match=r"checkpoint.pt: .*expected"):
        load_checkpoint(run_dir)
    line = one_line_error(CliRunner().invoke(main, ["train", "--out", str(run_dir), "--resume"]))
    assert "checkpoint.pt" in line and "expected" in line


def test_damaged_checkpoint_as_model_is_refused(run_dir):
    flip_byte(run_dir / "checkpoint.pt", (run_dir / "checkpoint.pt").stat().st_size - 100)
    with pytest.raises(ModelError, match="sha256"):
        inference.load_model(run_dir)


def test_train_out_refuses_an_existing_run(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.pt").write_bytes(b"earlier model")
    (run / "log.jsonl").write_text('{"kind": "meta"}\n')
    line = one_line_error(
        CliRunner().invoke(main, ["train", "recipes/gttnet/tiny.yaml", "--out", str(run), "--device", "cpu"])
    )
    assert str(run) in line and "--resume" in line and "--overwrite" in line
    assert (run / "model.pt").read_bytes() == b"earlier model"
    assert (run / "log.jsonl").read_text() == '{"kind": "meta"}\n'


_OVER = ["data.sources=[{generate: recipes/gttdata/tiny.yaml, max_train: 1, max_val: 1}]",
         "stages.0.steps=1", "stages.1.steps=1", "train.device=cpu"]  # fmt: skip


def _interrupted_run(tmp_path):
    """A run folder as an interrupted ``gttnet train`` leaves it: a checkpoint of the resolved recipe."""
    from gttnet.train.recipe import load_train_recipe, recipe_to_dict

    recipe = load_train_recipe("recipes/gttnet/tiny.yaml", _OVER)
    model = build_model(recipe.model.builder, **recipe.model.settings)
    opt = torch.optim.Adam(model.parameters())
    run = tmp_path / "r"
    run.mkdir()
    save_checkpoint(
        run, model=model, optimizer=opt, state=LoopState(global_step=1), recipe=recipe_to_dict(recipe)
    )
    return run


def test_resume_refuses_a_run_of_another_recipe(tmp_path):
    run = _interrupted_run(tmp_path)
    line = one_line_error(
        CliRunner().invoke(
            main, ["train", "recipes/gttnet/tiny.yaml", *_OVER, "seed=5", "--out", str(run), "--resume"]
        )  # fmt: skip
    )
    assert "another recipe" in line and "seed" in line


def test_resume_accepts_other_execution_settings():
    """More threads or data workers on another machine still continue the same run; what it learns may not change."""
    from gttnet.train.recipe import load_train_recipe
    from gttnet.train.rundir import _identity

    base = load_train_recipe("recipes/gttnet/tiny.yaml", _OVER)
    other = load_train_recipe("recipes/gttnet/tiny.yaml", [*_OVER, "train.threads=3", "data.num_workers=2"])
    assert other.train.threads == 3 and _identity(other) == _identity(base)
    assert _identity(
        load_train_recipe("recipes/gttnet/tiny.yaml", [*_OVER, "train.batch_size=3"])
    ) != _identity(base)


@pytest.mark.slow
def test_resume_continues_and_overwrite_replaces(tmp_path):
    from gttnet.train.loop import train
    from gttnet.train.recipe import load_train_recipe

    over = _OVER
    recipe = load_train_recipe("recipes/gttnet/tiny.yaml", over)
    train(recipe, out=tmp_path / "r", max_steps=1, progress=False)  # a real interrupted run
    res = CliRunner().invoke(
        main,
        ["train", "recipes/gttnet/tiny.yaml", *over, "--out", str(tmp_path / "r"), "--resume", "--quiet"],
    )
    assert res.exit_code == 0 and "finished" in res.output, res.output
    logs = [json.loads(x) for x in (tmp_path / "r/log.jsonl").read_text().splitlines()]
    assert sum(r["kind"] == "meta" for r in logs) == 1  # one run, one log
    res = CliRunner().invoke(
        main,
        [
            "train",
            "recipes/gttnet/tiny.yaml",
            *over,
            "seed=5",
            "--out",
            str(tmp_path / "r"),
            "--overwrite",
            "--quiet",
        ],  # fmt: skip
    )
    assert res.exit_code == 0, res.output
    logs = [json.loads(x) for x in (tmp_path / "r/log.jsonl").read_text().splitlines()]
    assert [r["seed"] for r in logs if r["kind"] == "meta"] == [5]


def test_checkpoint_on_a_full_disk_is_one_line_and_keeps_the_old_one(run_dir, small_fs):
    """A full disk while checkpointing: one line naming the file; the previous checkpoint survives."""
    from gttdata.errors import OutputError

    run = small_fs / "run"
    run.mkdir()
    (run / "checkpoint.pt").write_bytes((run_dir / "checkpoint.pt").read_bytes())
    (small_fs / "filler").write_bytes(b"\0" * (2 * 1024 * 1024 - 64 * 1024))
    model = build_model("gttnet_base", n_joints=31)  # larger than the space left
    with pytest.raises(OutputError, match=r"checkpoint.pt: cannot write: no space left on device"):
        save_checkpoint(run, model=model, optimizer=torch.optim.Adam(model.parameters()),
                        state=LoopState(global_step=9), recipe={"name": "x"})  # fmt: skip
    assert load_checkpoint(run)["state"].global_step == 3
    assert not [p for p in run.iterdir() if p.name.endswith(".tmp")]


def test_second_trainer_on_a_run_folder_is_refused(tmp_path):
    """One writer per run folder: a held lock refuses ``gttnet train --out`` with the holder's PID."""
    import os

    from gttdata.fileio import OutputLock

    run = tmp_path / "r"
    with OutputLock(run, "gttnet train"):  # flock conflicts across open files, even in one process
        line = one_line_error(
            CliRunner().invoke(
                main, ["train", "recipes/gttnet/tiny.yaml", *_OVER, "--out", str(run), "--resume"]
            )
        )
    assert f"PID {os.getpid()}" in line and str(run) in line


def test_overwrite_never_deletes_a_run_in_progress(tmp_path):
    """The lock is taken before ``--overwrite`` deletes anything."""
    from gttdata.fileio import OutputLock

    run = tmp_path / "r"
    run.mkdir()
    (run / "log.jsonl").write_text("running\n")
    with OutputLock(run, "gttnet train"):
        args = ["train", "recipes/gttnet/tiny.yaml", *_OVER, "--out", str(run), "--overwrite"]
        line = one_line_error(CliRunner().invoke(main, args))
    assert "PID" in line and (run / "log.jsonl").read_text() == "running\n"
