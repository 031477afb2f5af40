"""Item 9: ``5e-1`` is a number in recipes and overrides (PyYAML's YAML 1.1 read it as a string)."""

from __future__ import annotations

from gttdata.recipe import load_recipe
from gttnet.train.recipe import load_train_recipe
from tests.reliability.conftest import REPO, TINY


def test_exponent_override_is_a_number():
    recipe = load_recipe(TINY, ["capture.sigma_px=5e-1", "splits.0.n_samples=1e1"])
    assert recipe.capture.sigma_px.args == (0.5,) and recipe.splits[0].n_samples == 10


def test_exponent_in_a_recipe_file_is_a_number(tmp_path):
    text = (REPO / "recipes/gttdata/tiny.yaml").read_text().replace("sigma_px: 1.0", "sigma_px: 5e-1")
    assert "5e-1" in text
    path = tmp_path / "r.yaml"
    path.write_text(text)
    assert load_recipe(path).capture.sigma_px.args == (0.5,)


def test_exponent_in_a_training_override_is_a_number():
    recipe = load_train_recipe(REPO / "recipes/gttnet/tiny.yaml", ["stages.0.lr=1e-3"])
    assert recipe.stages[0].lr == 1e-3
