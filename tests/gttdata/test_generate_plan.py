"""build_sample: a pure function of (recipe, split, index); splits never share motions; all recipes build."""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from gttdata.cameras import ring_rig
from gttdata.capture.occlusion import visible_in_camera
from gttdata.capture.sample import CaptureSample
from gttdata.errors import RecipeError
from gttdata.generate_plan import (
    _file_motion,
    _procedural_motion,
    build_sample,
    list_motions,
    n_samples,
    sample_key,
    validate_inputs,
)
from gttdata.mocap.arrays import save_motion
from gttdata.mocap.procedural import generate_motion
from gttdata.recipe import load_recipe, parse_recipe, recipe_to_dict

RECIPES = Path(__file__).parents[2] / "recipes" / "gttdata"
ARRAYS = [
    f.name
    for f in fields(CaptureSample)
    if f.name not in ("name", "motion_name", "skeleton", "variant", "meta")
]


@pytest.fixture(scope="module")
def tiny():
    return load_recipe(RECIPES / "tiny.yaml")


def _same(a: CaptureSample, b: CaptureSample) -> bool:
    return (
        all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in ARRAYS) and a.meta == b.meta
    )


def test_counts_and_keys(tiny):
    assert n_samples(tiny) == {"train": 4, "val": 2, "test": 2}
    assert sample_key(tiny, "train", 17) == "train/000017"
    with pytest.raises(RecipeError, match="split: expected one of train, val, test, found 'dev'"):
        build_sample(tiny, "dev", 0)
    with pytest.raises(RecipeError, match="index: expected 0 <= index < 4"):
        build_sample(tiny, "train", 4)


def test_build_is_deterministic_and_order_independent(tiny):
    first = build_sample(tiny, "train", 2)
    for i in range(4):
        build_sample(tiny, "train", i)
    _procedural_motion.cache_clear()
    again = build_sample(tiny, "train", 2)
    assert len(first) == len(again) == 2
    for a, b in zip(first, again, strict=True):
        assert a.name == b.name == "train/000002" and a.variant == b.variant
        assert _same(a, b)
    other = build_sample(tiny, "train", 3)[0]
    assert not np.array_equal(first[0].keypoints_px, other.keypoints_px, equal_nan=True)
    test0 = build_sample(tiny, "test", 2 - 1)[0]
    assert test0.meta["split"] == "test"
    json.dumps([s.meta for s in first])  # meta is JSON-serialisable


def test_variants_follow_the_recipe(tiny):
    orig, rot = build_sample(tiny, "val", 0)
    assert (orig.variant, rot.variant) == ("orig", "global_rotation")
    assert orig.n_images == 24 and orig.n_cameras == 3 and orig.n_joints == 31
    T = np.asarray(rot.meta["variant_from_orig"])
    np.testing.assert_allclose(rot.points3d, orig.points3d @ T[:3, :3].T + T[:3, 3], atol=1e-12)
    assert np.array_equal(rot.keypoints_px, orig.keypoints_px, equal_nan=True)


@pytest.mark.parametrize("name", ["default", "paper", "tiny", "events", "multi_subject"])
def test_splits_share_no_motion_and_samples_use_their_split(name: str):
    recipe = load_recipe(RECIPES / f"{name}.yaml")
    per_split = {s.name: {r.name for r in list_motions(recipe, s.name)} for s in recipe.splits}
    names = list(per_split)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            assert not per_split[a] & per_split[b], (a, b)
    for split in names:
        for s in build_sample(recipe, split, 0)[:1]:
            used = {m["name"] for m in s.meta["motions"]}
            assert used <= per_split[split]


def test_default_recipe_draws_stay_in_range():
    recipe = load_recipe(RECIPES / "default.yaml")
    for i in range(6):
        s = build_sample(recipe, "train", i)[0]
        rig = s.meta["rig"]
        assert 3 <= rig["n_cameras"] <= 6 and 2.0 <= rig["radius_m"] <= 8.0
        assert set(s.meta["capture"]["fps_hz"]) <= {7.5, 15.0, 30.0}
        assert 0.0 <= s.meta["capture"]["sigma_px"] <= 5.0
        assert s.meta["min_cross_camera_gap_s"] > 0


def test_events_and_multi_subject_recipes():
    ev = build_sample(load_recipe(RECIPES / "events.yaml"), "train", 0)[0]
    assert ev.meta["n_events"] in (2, 3) and len(ev.meta["event_id"]) == ev.n_images
    assert set(ev.meta["event_id"]) == set(range(ev.meta["n_events"]))
    ms = build_sample(load_recipe(RECIPES / "multi_subject.yaml"), "train", 0)[0]
    assert ms.n_joints == 62 and ms.meta["n_subjects"] == 2
    roots = ms.points3d[:, [0, 31], :2].mean(axis=0)
    assert 1.5 - 1e-6 <= np.linalg.norm(roots[0] - roots[1]) <= 3.0 + 0.5
    offsets = np.array([m["offset_m"] for m in ms.meta["motions"]])
    assert 1.5 <= np.linalg.norm(offsets[0] - offsets[1]) <= 3.0


def test_file_sources_and_file_rig(tmp_path: Path):
    for k in range(2):
        save_motion(generate_motion("walk", seed=50 + k, duration_s=3.0), tmp_path / f"clip{k}.npz")
    ring_rig(5, radius_m=4.0).save(tmp_path / "rig.toml")
    data = {
        "splits": [
            {
                "name": "train",
                "n_samples": 2,
                "sources": [{"kind": "files", "paths": [str(tmp_path / "clip0.npz")]}],
            },
            {
                "name": "test",
                "n_samples": 1,
                "sources": [{"kind": "files", "paths": [str(tmp_path / "clip1*.npz")]}],
            },
        ],
        "rig": {"kind": "file", "path": str(tmp_path / "rig.toml")},
        "capture": {"window_s": 1.0},
    }
    recipe = parse_recipe(data)
    assert validate_inputs(recipe) == {"train": 1, "test": 1}
    s = build_sample(recipe, "test", 0)[0]
    assert s.n_cameras == 5 and s.motion_name == "clip1" and s.meta["rig"]["kind"] == "file"
    assert _file_motion.cache_info().currsize >= 1
    data["splits"][1]["sources"][0]["paths"] = [str(tmp_path / "clip0.npz").replace("clip0", "clip?")]
    with pytest.raises(RecipeError, match="expected motions disjoint across splits"):
        validate_inputs(parse_recipe(data))
    data["splits"][1]["sources"][0]["paths"] = [str(tmp_path / "missing*.npz")]
    with pytest.raises(RecipeError, match=r"splits.test.sources\[0\].paths: expected existing motion files"):
        validate_inputs(parse_recipe(data))


def test_cmu_recipe_builds_from_the_motion_cache(mocap_dir: Path):
    recipe = load_recipe(RECIPES / "cmu.yaml")
    assert validate_inputs(recipe)["test"] == 1
    s = build_sample(recipe, "test", 0)[0]
    assert s.motion_name == "01_03" and s.n_images == 300 and s.n_joints == 31


def test_recipe_noise_and_missing_rate_reach_the_samples(tiny):
    """sigma_px and joint_drop_rate set in a recipe show up in built samples within 5 standard errors."""
    data = recipe_to_dict(tiny)
    data["capture"].update(sigma_px=3.0, joint_drop_rate=0.3, window_s=2.5, fps_hz=30.0)
    data["augmentations"] = []
    recipe = parse_recipe(data)
    resid, kept = [], []
    for i in range(4):
        s = build_sample(recipe, "train", i)[0]
        in_view = visible_in_camera(
            s.keypoints_gt_px.astype(float), np.ones(s.visible.shape), s.image_size[s.cam_id]
        )
        kept.append(s.visible[in_view])
        resid.append((s.keypoints_px - s.keypoints_gt_px)[s.visible].astype(float).ravel())
    r, k = np.concatenate(resid), np.concatenate(kept)
    assert abs(r.std() - 3.0) < 5 * 3.0 / np.sqrt(2 * (r.size - 1))
    assert abs((1 - k.mean()) - 0.3) < 5 * np.sqrt(0.3 * 0.7 / k.size)
