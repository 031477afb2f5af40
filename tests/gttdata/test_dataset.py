"""CaptureDataset: sequencing views expose only what they allow; random access; variants; determinism."""

from __future__ import annotations

import dataclasses
import json
import pickle

import numpy as np
import pytest

from gttdata.capture.views import GroundTruth, Observations
from gttdata.dataset import CaptureDataset, DatasetReader
from gttdata.generation import generate_dataset
from gttdata.recipe import load_recipe


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """recipes/gttdata/tiny.yaml (train: 4 samples of 24 images, variants orig + global_rotation), 3 per shard."""
    out = tmp_path_factory.mktemp("tiny")
    recipe = load_recipe("recipes/gttdata/tiny.yaml", ["shard.samples_per_shard=3"])
    generate_dataset(dataclasses.replace(recipe, output_dir=str(out)), progress=False)
    return out


@pytest.mark.parametrize(
    ("sequencing", "keys"),
    [("none", set()), ("partial", {"stream_index"}), ("full", {"stream_index", "timestamp_s"})],
)
def test_views_expose_only_what_they_allow(root, sequencing, keys):
    ds = CaptureDataset(root, split="train", sequencing=sequencing)
    item = ds[1]
    base = {
        "sequencing",
        "cam_id",
        "K",
        "cam_from_world",
        "keypoints_px",
        "visible",
        "image_size",
        "skeleton",
    }
    assert set(item["obs"]) == base | keys
    assert item["obs"]["sequencing"] == sequencing == item["sequencing"]
    assert not {"points3d", "global_order", "affinity_nbr", "affinity_w", "perm"} & set(item["obs"])
    assert json.loads(item["obs"]["skeleton"])["name"] == "cmu31"
    gt = item["gt"]
    order = gt["global_order"]
    if sequencing == "full":
        np.testing.assert_array_equal(order, np.arange(order.size))
        assert np.all(np.diff(item["obs"]["timestamp_s"]) > 0)
    elif sequencing == "partial":
        cam, idx = item["obs"]["cam_id"], item["obs"]["stream_index"]
        assert np.all(np.diff(cam) >= 0)
        for c in np.unique(cam):
            np.testing.assert_array_equal(idx[cam == c], np.arange((cam == c).sum()))
    else:
        assert not np.array_equal(order, np.arange(order.size)), "'none' must hide the time order"


def test_random_access_matches_stored_samples(root):
    ds = CaptureDataset(root, split="train", sequencing="none")
    reader = DatasetReader(root, "train")
    for i in np.random.default_rng(0).permutation(len(ds)):
        item = ds[int(i)]
        stored = reader.read_sample(int(i))
        perm = item["gt"]["perm"]
        assert item["name"] == stored.name == f"train/{int(i):06d}"
        np.testing.assert_array_equal(item["gt"]["points3d"], stored.points3d[perm])
        np.testing.assert_array_equal(item["obs"]["keypoints_px"], stored.keypoints_px[perm])
        np.testing.assert_array_equal(item["gt"]["timestamp_s"], stored.timestamp_s[perm])


def test_view_matches_getitem(root):
    ds = CaptureDataset(root, split="val", sequencing=["none", "partial", "full"], seed=3)
    for i in range(len(ds)):
        obs, gt = ds.view(i)
        assert isinstance(obs, Observations) and isinstance(gt, GroundTruth)
        item = ds[i]
        assert obs.sequencing == item["sequencing"]
        np.testing.assert_array_equal(obs.cam_id, item["obs"]["cam_id"])
        np.testing.assert_array_equal(gt.points3d, item["gt"]["points3d"])


def test_mixed_sequencing_is_deterministic_per_epoch(root):
    a = CaptureDataset(root, split="train", sequencing=["none", "partial", "full"], variant="all", seed=1)
    b = CaptureDataset(root, split="train", sequencing=["none", "partial", "full"], variant="all", seed=1)
    draws = [a[i]["sequencing"] for i in range(len(a))]
    assert draws == [b[i]["sequencing"] for i in range(len(b))]
    seen = set()
    for epoch in range(6):
        a.set_epoch(epoch)
        seen.update(a[i]["sequencing"] for i in range(len(a)))
    assert seen == {"none", "partial", "full"}


def test_variants(root):
    ds = CaptureDataset(root, split="train", variant="all")
    assert len(ds) == 8 and ds.variants == ("orig", "global_rotation")
    assert [ds[i]["variant"] for i in range(4)] == ["orig", "global_rotation"] * 2
    assert ds[0]["name"] == ds[1]["name"]
    only = CaptureDataset(root, split="train", variant=["global_rotation"])
    assert len(only) == 4 and only[2]["variant"] == "global_rotation"
    with pytest.raises(ValueError, match="stored variants"):
        CaptureDataset(root, split="train", variant="mirror")
    with pytest.raises(ValueError, match="sequencing must be one of"):
        CaptureDataset(root, split="train", sequencing="sometimes")
    with pytest.raises(IndexError, match="out of range"):
        ds[8]


def test_pickles_without_handles(root):
    ds = CaptureDataset(root, split="test", sequencing="full")
    first = ds[0]
    clone = pickle.loads(pickle.dumps(ds))
    assert all(s._file is None for s in clone.reader.shards)
    np.testing.assert_array_equal(clone[0]["gt"]["points3d"], first["gt"]["points3d"])
