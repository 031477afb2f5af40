"""Item 9: nested recipe paths resolve against the recipe's own folder, not the working directory."""

from __future__ import annotations

from pathlib import Path

from click.testing import CliRunner

from gttnet.cli import main
from gttnet.evaluate.recipe import load_eval_recipe
from gttnet.train.recipe import load_train_recipe
from tests.reliability.conftest import REPO, one_line_error


def test_nested_recipes_resolve_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # outside the repository
    train = load_train_recipe(REPO / "recipes/gttnet/tiny.yaml")
    assert all(Path(s.generate).is_file() for s in train.data.sources)
    ev = load_eval_recipe(REPO / "recipes/gttnet/eval_smoke.yaml")
    assert Path(ev.data.generate).is_file()


def test_evaluate_by_absolute_path_runs_outside_the_repository(tmp_path, monkeypatch):
    """It failed with 'recipes/gttdata/tiny.yaml: recipe file not found'."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "eval"
    args = ["evaluate", str(REPO / "recipes/gttnet/eval_smoke.yaml"), "methods=[pseudo]", "sequencing=[full]",
            "data.n_sequences=1", "sweeps=[{name: noise, variable: capture.sigma_px, values: [0]}]",
            f"output_dir={out}"]  # fmt: skip
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert any(out.rglob("*.csv"))


def test_evaluate_recipe_error_leaves_no_half_made_folder(tmp_path, monkeypatch):
    """A failing evaluation recipe left a half-made run folder behind."""
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "eval"
    args = ["evaluate", str(REPO / "recipes/gttnet/eval_smoke.yaml"), "data.generate=missing.yaml",
            f"output_dir={out}"]  # fmt: skip
    line = one_line_error(CliRunner().invoke(main, args))
    assert "missing.yaml" in line
    assert not out.exists()
