"""Every manifest registered in manifests/ is well-formed and agrees with its own recipe."""

from __future__ import annotations

from pathlib import Path

import pytest

from gttdata.manifest import load_manifest
from gttdata.recipe import parse_recipe, recipe_hash

MANIFESTS = sorted((Path(__file__).resolve().parents[1] / "manifests").glob("*.json"))


def test_default_dataset_is_registered():
    assert "default" in {p.stem for p in MANIFESTS}


@pytest.mark.parametrize("path", MANIFESTS, ids=[p.stem for p in MANIFESTS])
def test_manifest_schema_and_recipe_hash(path):
    manifest = load_manifest(path)
    assert manifest.name == path.stem
    recipe = parse_recipe(manifest.recipe, source=str(path))
    assert recipe_hash(recipe) == manifest.recipe_hash
    assert manifest.shards, "a registered dataset lists its shards"
    for shard in manifest.shards:
        assert len(shard.sha256) == 64 and shard.bytes > 0 and shard.n_samples > 0
    assert sum(s.n_samples for s in manifest.shards) == sum(
        sp["n_samples"] for sp in manifest.recipe["splits"]
    )
