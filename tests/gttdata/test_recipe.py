"""Recipe loading: every shipped recipe validates; bad keys, types and ranges fail in one line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from gttdata.errors import RecipeError
from gttdata.recipe import (
    GenerateRecipe,
    Param,
    ProceduralSource,
    load_recipe,
    parse_recipe,
    recipe_hash,
    recipe_to_dict,
)

RECIPES = sorted((Path(__file__).parents[2] / "recipes" / "gttdata").glob("*.yaml"))

MINIMAL = {"splits": [{"name": "train", "n_samples": 3, "sources": [{"kind": "procedural", "count": 2}]}]}


def _write(tmp_path: Path, data: dict) -> Path:
    path = tmp_path / "recipe.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_recipes_exist():
    names = {p.stem for p in RECIPES}
    assert {"default", "paper", "tiny", "cmu", "events", "multi_subject"} <= names


@pytest.mark.parametrize("path", RECIPES, ids=lambda p: p.stem)
def test_every_recipe_validates(path: Path):
    recipe = load_recipe(path)
    assert isinstance(recipe, GenerateRecipe)
    assert recipe.splits
    first = path.read_text().splitlines()[0]
    assert first.startswith("# ") and f"gttdata generate recipes/gttdata/{path.name}" in first
    # Round trip through plain data gives the same recipe and hash.
    again = parse_recipe(recipe_to_dict(recipe))
    assert again == recipe
    assert recipe_hash(again) == recipe_hash(recipe)


@pytest.mark.parametrize(
    ("override", "message"),
    [
        (
            "capture.sigma_px=abc",
            "recipe.yaml: capture.sigma_px: expected a number >= 0 or a distribution, found 'abc'",
        ),
        (
            "capture.sigma_px=-1",
            "recipe.yaml: capture.sigma_px: expected a number >= 0 or a distribution, found -1",
        ),
        ("capture.sigmapx=1", "recipe.yaml: capture.sigmapx: unknown key"),
        ("bogus=1", "recipe.yaml: bogus: unknown key"),
        ("capture.outlier_rate=1.5", "recipe.yaml: capture.outlier_rate: expected a number >= 0 and <= 1"),
        (
            "capture.sigma_px={uniform: [3, 1]}",
            "recipe.yaml: capture.sigma_px.uniform: expected [a, b] with a <= b",
        ),
        ("capture.sigma_px={uniform: [-1, 1]}", "recipe.yaml: capture.sigma_px.uniform: expected bounds"),
        (
            "capture.sigma_px={gauss: [0, 1]}",
            "recipe.yaml: capture.sigma_px: expected a number >= 0 or a distribution",
        ),
        ("capture.sigma_px={normal: [1, -1]}", "recipe.yaml: capture.sigma_px.normal: expected [mu, sigma]"),
        (
            "capture.fps_hz=[30, 0]",
            "recipe.yaml: capture.fps_hz: expected a list of numbers > 0 and <= 10000, found 0",
        ),
        ("capture.stagger=sometimes", "recipe.yaml: capture.stagger: expected one of 'even', 'random'"),
        ("rig.n_cameras=2.5", "recipe.yaml: rig.n_cameras: expected an integer >= 2"),
        ("rig.kind=sphere", "recipe.yaml: rig.kind: expected one of 'ring', 'file'"),
        ("rig.image_size=[1000]", "recipe.yaml: rig.image_size: expected a list of 2 values"),
        ("seed=true", "recipe.yaml: seed: expected an integer >= 0, found True"),
        ("shard.compression=zstd", "recipe.yaml: shard.compression: expected one of 'none', 'gzip', 'lzf'"),
        ("splits.train.n_samples=-3", "recipe.yaml: splits[0].n_samples: expected an integer >= 0"),
        ("splits.train.sources.0.kind=file", "recipe.yaml: splits[0].sources[0].kind: expected one of"),
        (
            "motion_augment.mirror_prob=2",
            "recipe.yaml: motion_augment.mirror_prob: expected a number >= 0 and <= 1",
        ),
        ("augmentations=[{name: spin}]", "recipe.yaml: augmentations[0].name: expected one of"),
        (
            "augmentations=[{name: global_rotation, params: {axis: x}}]",
            "recipe.yaml: augmentations[0].params.axis: expected one of",
        ),
        (
            "augmentations=[{name: global_rotation, params: {speed: 1}}]",
            "recipe.yaml: augmentations[0].params.speed: unknown",
        ),
        (
            "augmentations=[{name: camera_perturbation, params: {rot_deg: abc}}]",
            "recipe.yaml: augmentations[0].params.rot_deg: expected a number in [0, 45]",
        ),
    ],
)
def test_bad_values_fail_in_one_line(tmp_path: Path, override: str, message: str):
    path = _write(tmp_path, MINIMAL)
    with pytest.raises(RecipeError) as info:
        load_recipe(path, [override])
    text = str(info.value).replace(str(path), "recipe.yaml")
    assert "\n" not in text
    assert text.startswith(message), text


def test_missing_required_and_bad_yaml(tmp_path: Path):
    path = _write(tmp_path, {"seed": 1})
    with pytest.raises(RecipeError, match=r"splits: expected a value \(this key is required\)"):
        load_recipe(path)
    path.write_text("splits: [\n")
    with pytest.raises(RecipeError, match="not valid YAML"):
        load_recipe(path)
    with pytest.raises(RecipeError, match="recipe file not found"):
        load_recipe(tmp_path / "nope.yaml")
    with pytest.raises(RecipeError, match="expected key.sub=value"):
        load_recipe(_write(tmp_path, MINIMAL), ["capture.sigma_px"])
    with pytest.raises(RecipeError, match="no list element named or numbered 'nope'"):
        load_recipe(_write(tmp_path, MINIMAL), ["splits.nope.n_samples=1"])


def test_overrides(tmp_path: Path):
    path = _write(tmp_path, MINIMAL)
    r = load_recipe(
        path,
        [
            "capture.sigma_px=4",
            "splits.train.n_samples=10",
            "splits.0.sources.0.count=7",
            "capture.fps_hz=[30, 15, 7.5]",
            "capture.joint_drop_rate={uniform: [0.1, 0.3]}",
            "rig.n_cameras={choice: [3, 5]}",
            "name=sweep",
        ],
    )
    assert r.capture.sigma_px == Param("value", (4.0,))
    assert r.splits[0].n_samples == 10 and r.splits[0].sources[0].count == 7
    assert r.capture.fps_hz == Param("list", (30.0, 15.0, 7.5))
    assert r.capture.joint_drop_rate == Param("uniform", (0.1, 0.3))
    assert r.rig.n_cameras == Param("choice", (3, 5))
    assert r.name == "sweep"
    assert recipe_hash(r) != recipe_hash(load_recipe(path))


def test_defaults_live_in_dataclasses():
    r = parse_recipe(MINIMAL)
    assert r.capture.sigma_px == Param.of(2.0) and r.rig.n_cameras == Param.of(4)
    assert r.splits[0].sources[0] == ProceduralSource(count=2)
    # 2 and 2.0 are the same recipe (canonical JSON).
    a = parse_recipe({**MINIMAL, "capture": {"sigma_px": 2}})
    assert recipe_hash(a) == recipe_hash(r)
    assert len(recipe_hash(r)) == 64


def test_splits_may_not_share_motions():
    train = {"name": "train", "n_samples": 1, "sources": [{"kind": "procedural", "count": 10, "seed": 0}]}
    test = {"name": "test", "n_samples": 1, "sources": [{"kind": "procedural", "count": 5, "seed": 9}]}
    with pytest.raises(
        RecipeError, match=r"splits\[1\].sources\[0\].seed: expected procedural seeds disjoint"
    ):
        parse_recipe({"splits": [train, test]})
    test["sources"][0]["seed"] = 10
    parse_recipe({"splits": [train, test]})
    files = {"kind": "files", "paths": ["cache:01_01.bvh"]}
    with pytest.raises(RecipeError, match="expected motion files disjoint across splits"):
        parse_recipe({"splits": [{**train, "sources": [files]}, {**test, "sources": [files]}]})
    with pytest.raises(RecipeError, match=r"splits\[1\].name: expected a unique split name"):
        parse_recipe({"splits": [train, {**test, "name": "train"}]})


def test_param_draws_respect_kind_and_range():
    rng = np.random.default_rng(0)
    ints = Param("uniform", (3, 6), integer=True, lo=1).draw(rng, size=2000)
    assert ints.dtype == np.int64 and set(ints.tolist()) == {3, 4, 5, 6}
    clipped = Param("normal", (0.0, 1.0), lo=0.0).draw(rng, size=2000)
    assert clipped.min() == 0.0 and clipped.max() > 1.0
    assert set(Param("choice", (7.5, 15.0, 30.0)).draw(rng, size=300).tolist()) == {7.5, 15.0, 30.0}
    assert Param("list", (30.0, 15.0)).draw(rng, size=3).tolist() == [30.0, 15.0, 30.0]
    assert float(Param.of(2.5).draw(rng)) == 2.5


def test_relative_paths_resolve_against_the_recipe_folder(tmp_path: Path, monkeypatch):
    folder = tmp_path / "recipes"
    folder.mkdir()
    data = yaml.safe_load(Path("recipes/gttdata/tiny.yaml").read_text())
    data["splits"][0]["sources"] = [
        {"kind": "files", "paths": ["motions/a.bvh", "cache:01_01.bvh", "/abs/b.bvh"]}
    ]
    data["rig"] = {"kind": "file", "path": "rig.toml"}
    (folder / "r.yaml").write_text(yaml.safe_dump(data))
    monkeypatch.chdir(tmp_path)
    r = load_recipe("recipes/r.yaml")
    assert r.splits[0].sources[0].paths == (str(folder / "motions/a.bvh"), "cache:01_01.bvh", "/abs/b.bvh")
    assert r.rig.path == str(folder / "rig.toml")
    assert load_recipe("recipes/r.yaml", ["rig.path=here.toml"]).rig.path == "here.toml"  # typed in a shell
