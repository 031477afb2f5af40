"""Manifest build / write / load / verify, and DatasetReader's global indexing over shards."""

from __future__ import annotations

import dataclasses
import json

import pytest

from gttdata.dataset import DatasetReader
from gttdata.errors import ManifestError
from gttdata.generation import generate_dataset
from gttdata.manifest import (
    MANIFEST_NAME,
    Manifest,
    build_manifest,
    file_sha256,
    load_manifest,
    register_manifest,
    verify_manifest,
)
from gttdata.recipe import load_recipe
from gttdata.shards.schema import SCHEMA_VERSION

TINY = "recipes/gttdata/tiny.yaml"


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    """recipes/gttdata/tiny.yaml with 3 samples per shard: train 4 (2 shards), val 2, test 2."""
    root = tmp_path_factory.mktemp("tiny")
    recipe = load_recipe(TINY, ["shard.samples_per_shard=3"])
    generate_dataset(dataclasses.replace(recipe, output_dir=str(root)), progress=False)
    return root


@pytest.fixture
def copy_root(tiny_root, tmp_path):
    import shutil

    dst = tmp_path / "copy"
    shutil.copytree(tiny_root, dst)
    return dst


def test_manifest_contents(tiny_root):
    m = load_manifest(tiny_root)
    assert m.name == "tiny" and m.seed == 7 and m.schema_version == SCHEMA_VERSION
    assert list(m.splits) == ["train", "val", "test"]
    assert {k: v["n_samples"] for k, v in m.splits.items()} == {"train": 4, "val": 2, "test": 2}
    assert [e.path for e in m.shards_of("train")] == ["train/shard-00000.h5", "train/shard-00001.h5"]
    assert m.variants == ("orig", "global_rotation")
    assert m.skeleton["name"] == "cmu31" and m.rig["kind"] == "ring" and m.recipe["output_dir"] == ""
    st = m.splits["train"]["statistics"]
    assert st["n_images"] == 4 * 24 and 0.0 < st["missing_rate"] < 0.3 and st["sigma_px_mean"] == 1.0
    for e in m.shards:
        assert e.sha256 == file_sha256(tiny_root / e.path) and e.bytes == (tiny_root / e.path).stat().st_size


def test_round_trip_and_rebuild_identical(tiny_root):
    m = load_manifest(tiny_root)
    assert Manifest.from_dict(json.loads(json.dumps(m.to_dict()))) == m
    assert build_manifest(tiny_root) == m


def test_verify_clean(tiny_root):
    assert verify_manifest(tiny_root) == []
    assert verify_manifest(tiny_root, deep=True) == []


def test_verify_names_each_bad_shard(copy_root):
    flip = copy_root / "train/shard-00001.h5"
    data = bytearray(flip.read_bytes())
    data[len(data) // 2] ^= 0x01
    flip.write_bytes(bytes(data))
    cut = copy_root / "val/shard-00000.h5"
    cut.write_bytes(cut.read_bytes()[:1000])
    (copy_root / "test/shard-00000.h5").unlink()
    (copy_root / "train/shard-00007.h5").write_bytes(b"")
    (copy_root / "train/shard-00002.h5.tmp").write_bytes(b"")
    problems = verify_manifest(copy_root)
    text = "\n".join(problems)
    assert len(problems) == 5, text
    assert "train/shard-00001.h5: sha256" in text
    assert "val/shard-00000.h5: size: expected" in text
    assert "test/shard-00000.h5: missing" in text
    assert "train/shard-00007.h5: shard not listed" in text
    assert "train/shard-00002.h5.tmp: leftover temporary" in text


def test_load_errors(tmp_path, tiny_root):
    with pytest.raises(ManifestError, match="no manifest.*gttdata manifest"):
        load_manifest(tmp_path)
    (tmp_path / MANIFEST_NAME).write_text("{oops")
    with pytest.raises(ManifestError, match="not valid JSON \\(line 1"):
        load_manifest(tmp_path)
    d = load_manifest(tiny_root).to_dict()
    del d["recipe_hash"]
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(d))
    with pytest.raises(ManifestError, match="field 'recipe_hash' is missing"):
        load_manifest(tmp_path)
    d = {**load_manifest(tiny_root).to_dict(), "manifest_version": "9.0"}
    (tmp_path / MANIFEST_NAME).write_text(json.dumps(d))
    with pytest.raises(ManifestError, match="manifest_version: expected 1.x, found '9.0'"):
        load_manifest(tmp_path)


def test_build_refuses_missing_samples(copy_root):
    (copy_root / "train/shard-00000.h5").unlink()
    with pytest.raises(ManifestError, match="train/shard-00001.h5: first_index: expected 0, found 3"):
        build_manifest(copy_root)


def test_build_refuses_incomplete_split(copy_root):
    (copy_root / "train/shard-00001.h5").unlink()
    with pytest.raises(ManifestError, match="split 'train': expected 4 samples \\(recipe\\), found 3"):
        build_manifest(copy_root)


def test_build_refuses_mixed_recipes(copy_root, tmp_path):
    other = tmp_path / "other"
    recipe = load_recipe(TINY, ["seed=8", "shard.samples_per_shard=3"])
    generate_dataset(dataclasses.replace(recipe, output_dir=str(other)), shard_range="0:1", progress=False)
    (copy_root / "train/shard-00000.h5").write_bytes((other / "train/shard-00000.h5").read_bytes())
    with pytest.raises(ManifestError, match="shards of different recipes"):
        build_manifest(copy_root)


def test_register(tiny_root, tmp_path):
    m = load_manifest(tiny_root)
    path = register_manifest(m, tmp_path, location="data/gttdata/tiny")
    assert path.name == "tiny.json"
    data = json.loads(path.read_text())
    assert data["location"] == "data/gttdata/tiny" and data["recipe_hash"] == m.recipe_hash
    with pytest.raises(ManifestError, match="manifests/ folder"):
        register_manifest(m, tmp_path / "nope", location="x")


def test_dataset_reader_global_index(tiny_root):
    train = DatasetReader(tiny_root, "train")
    assert len(train) == 4 and len(DatasetReader(tiny_root)) == 8
    for i in range(4):
        assert train.read_sample(i).name == f"train/{i:06d}"
    shard, local = train.locate(3)
    assert shard.path.name == "shard-00001.h5" and local == 0
    everything = DatasetReader(tiny_root)
    assert everything.read_sample(4).name == "val/000000" and everything.read_sample(-1).name == "test/000001"
    assert train.read_sample(1, "global_rotation").variant == "global_rotation"
    with pytest.raises(IndexError):
        train.read_sample(4)
    with pytest.raises(ManifestError, match="no split 'nope'; splits: train, val, test"):
        DatasetReader(tiny_root, "nope")
