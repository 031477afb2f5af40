"""Topology-diverse data.

Topology-diverse data: procedural hand and quadruped, topology augmentation, recipes with a
``skeleton`` key, mixed-topology shards and loader, previews of any skeleton.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from gttdata.augment.topology import marker_map, merge_map, subset_map
from gttdata.errors import RecipeError
from gttdata.generate_plan import build_sample
from gttdata.mocap.procedural import (
    HAND_KINDS,
    QUADRUPED_KINDS,
    generate_hand_motion,
    generate_quadruped_motion,
    generate_skeleton_motion,
    kinds_for_skeleton,
)
from gttdata.recipe import load_recipe, parse_recipe, recipe_hash, recipe_to_dict
from gttdata.skeletons import get_skeleton, skeleton_family

MIXED = "recipes/gttdata/tiny_topologies.yaml"


@pytest.mark.parametrize("kind", HAND_KINDS)
def test_hand_bone_lengths_constant_and_kinds_move_fingers(kind):
    m = generate_hand_motion(kind, seed=4, duration_s=2.0, fps_hz=30.0)
    assert m.skeleton == get_skeleton("hand21") and m.positions.shape == (61, 21, 3)
    bl = m.bone_lengths()
    assert np.abs(bl - bl[0]).max() < 1e-12
    tips = m.positions[:, [4, 8, 12, 16, 20]] - m.positions[:, :1]
    reach = np.linalg.norm(tips, axis=-1)  # (T, 5) wrist-to-fingertip distances
    if kind in ("grasp", "point"):
        assert (reach.max(0) - reach.min(0))[2] > 0.05  # the middle finger curls and opens
    if kind == "point":
        assert np.argmax(reach.min(0)[1:]) == 0  # the index finger stays extended
    if kind == "wave":
        assert np.ptp(m.positions[:, 0, :2], axis=0).max() > 0.05  # the hand swings


@pytest.mark.parametrize("kind", QUADRUPED_KINDS)
def test_quadruped_bone_lengths_constant_and_paws_planted(kind):
    fps = 60.0
    m = generate_quadruped_motion(kind, seed=3, duration_s=3.0, fps_hz=fps)
    sk = m.skeleton
    assert sk.name == "quadruped36" and 30 <= sk.n_joints <= 45
    bl = m.bone_lengths()
    assert np.abs(bl - bl[0]).max() < 1e-12
    assert m.positions[..., 2].min() > -1e-9  # nothing below the floor
    travel = np.linalg.norm(m.positions[-1, 0, :2] - m.positions[0, 0, :2])
    for paw in ("left_front_paw", "right_front_paw", "left_hind_paw", "right_hind_paw"):
        p = m.positions[:, sk.index(paw)]
        speed = np.linalg.norm(np.diff(p, axis=0), axis=-1) * fps
        planted = speed < 1e-6
        # A planted paw is still and on the floor; every gait keeps each paw planted a good part of the time.
        assert planted.mean() > (0.95 if kind == "sit" else 0.3), (paw, planted.mean())
        assert np.abs(p[1:][planted, 2] - p[:, 2].min()).max() < 1e-9
    if kind == "sit":
        assert travel < 0.1
        pelvis = m.positions[:, 0, 2]
        assert pelvis.min() < 0.7 * pelvis.max()  # it sits down
    else:
        assert travel > 0.5


def test_quadruped_turn_changes_heading():
    m = generate_quadruped_motion("turn", seed=1, duration_s=3.0, fps_hz=30.0)
    sk = m.skeleton
    fwd = m.positions[:, sk.index("withers"), :2] - m.positions[:, sk.index("pelvis"), :2]
    a0, a1 = np.arctan2(fwd[0, 1], fwd[0, 0]), np.arctan2(fwd[-1, 1], fwd[-1, 0])
    assert abs(np.angle(np.exp(1j * (a1 - a0)))) > 0.8


def test_skeleton_motion_dispatch_and_kinds():
    assert kinds_for_skeleton("hand21") == HAND_KINDS and kinds_for_skeleton("quadruped36") == QUADRUPED_KINDS
    coco = generate_skeleton_motion("coco17", "walk", seed=2, duration_s=0.5, fps_hz=30.0)
    assert coco.skeleton.name == "coco17" and coco.positions.shape[1] == 17
    with pytest.raises(ValueError, match="grasp"):
        generate_skeleton_motion("hand21", "walk", seed=0)


@pytest.mark.parametrize("name", ["coco17", "hand21", "quadruped36"])
def test_topology_maps_are_trees_over_the_same_body(name):
    sk = get_skeleton(name)
    motion = generate_skeleton_motion(name, kinds_for_skeleton(name)[0], seed=1, duration_s=0.3, fps_hz=30.0)
    for seed in range(5):
        for make in (subset_map, merge_map, marker_map):
            tm = make(sk, np.random.default_rng(seed))
            new = tm.skeleton
            np.testing.assert_allclose(tm.weights.sum(axis=1), 1.0)
            assert len(new.bones) == new.n_joints - 1  # still one tree
            assert skeleton_family(new.name) == skeleton_family(name)
            out = tm(motion)
            assert out.positions.shape == (motion.n_frames, new.n_joints, 3)
            if make is subset_map:
                assert new.n_joints >= 0.5 * sk.n_joints
                kept = [sk.index(n) for n in new.joint_names]
                np.testing.assert_array_equal(out.positions, motion.positions[:, kept])
            if make is merge_map:
                assert new.n_joints < sk.n_joints
            if make is marker_map:  # markers lie on the segment hull, within the bone's reach of the joint
                d = np.linalg.norm(out.positions - motion.positions, axis=-1)
                assert 0 < d.max() < 0.5 * motion.bone_lengths().max() + 1e-9


def test_recipe_skeleton_key_validated_and_old_hash_kept():
    tiny = load_recipe("recipes/gttdata/tiny.yaml")
    assert "skeleton" not in json.dumps(recipe_to_dict(tiny))  # defaults leave the canonical form alone
    data = recipe_to_dict(tiny)
    assert recipe_hash(parse_recipe(data)) == recipe_hash(tiny)
    data["splits"][0]["sources"][0]["skeleton"] = "coco19"
    with pytest.raises(
        RecipeError, match=r"sources\[0\]\.skeleton: expected one of .*coco17.*found 'coco19'"
    ):
        parse_recipe(data, source="r.yaml")
    data["splits"][0]["sources"][0]["skeleton"] = "hand21"
    with pytest.raises(RecipeError, match=r"kinds: expected kinds among grasp"):
        parse_recipe(
            dict(
                data,
                splits=[
                    dict(data["splits"][0], sources=[dict(data["splits"][0]["sources"][0], kinds=["walk"])])
                ],
            )
        )
    data["splits"][0]["sources"] = [{"kind": "files", "paths": ["x.c3d"], "skeleton": "hand21"}]
    with pytest.raises(RecipeError, match="derived from CMU-31 files"):
        parse_recipe(data)


def test_recipe_refuses_mixed_topologies_in_multi_subject_samples():
    data = recipe_to_dict(load_recipe(MIXED))
    data["scene"]["n_subjects"] = 2
    with pytest.raises(RecipeError, match="one skeleton per split"):
        parse_recipe(data)


@pytest.fixture(scope="module")
def mixed_dataset(tmp_path_factory):
    from gttdata.generation import generate_dataset

    root = tmp_path_factory.mktemp("mixed")
    recipe = dataclasses.replace(load_recipe(MIXED), output_dir=str(root))
    generate_dataset(recipe, progress=False)
    return root, recipe


def test_mixed_topology_shards_round_trip(mixed_dataset):
    from gttdata.dataset import DatasetReader
    from gttdata.manifest import load_manifest

    root, recipe = mixed_dataset
    reader = DatasetReader(root, "train")
    names = set()
    for i in range(len(reader)):
        got = reader.read_sample(i)
        want = build_sample(recipe, "train", i)[0]
        assert got.skeleton == want.skeleton and got.skeleton.extra_bones == want.skeleton.extra_bones
        np.testing.assert_array_equal(got.keypoints_px, want.keypoints_px)
        np.testing.assert_allclose(got.points3d, want.points3d, atol=1e-6)
        names.add(got.skeleton.name)
    assert len({skeleton_family(n) for n in names}) == 3  # human, hand and quadruped in one split
    counts = load_manifest(root).splits["train"]["skeletons"]
    assert sum(counts.values()) == len(reader) and set(counts) == names


def test_loader_and_collate_handle_mixed_joint_counts(mixed_dataset):
    from gttdata.dataset import CaptureDataset

    root, _ = mixed_dataset
    ds = CaptureDataset(root, split="train", sequencing=["none", "full"])
    joints = set()
    for i in range(len(ds)):
        item = ds[i]
        sk = json.loads(item["obs"]["skeleton"])
        j = len(sk["joint_names"])
        assert item["obs"]["keypoints_px"].shape[1:] == (j, 2) and item["gt"]["points3d"].shape[1:] == (j, 3)
        joints.add(j)
    assert len(joints) >= 3


def test_previews_of_every_family_are_not_blank(mixed_dataset):
    from gttdata.dataset import DatasetReader
    from gttdata.preview.overlay import crop_windows, draw_overlay

    root, _ = mixed_dataset
    reader = DatasetReader(root, "train")
    seen = set()
    for i in range(len(reader)):
        s = reader.read_sample(i)
        n = int(np.argmax(s.visible.sum(axis=1)))
        win = crop_windows(s)[int(s.cam_id[n])]
        img = draw_overlay(s, n, window=win, width_px=200, text=False)
        empty = dataclasses.replace(
            s, keypoints_px=np.full_like(s.keypoints_px, np.nan), keypoints_gt_px=np.full_like(s.keypoints_gt_px, np.nan),
            visible=np.zeros_like(s.visible),
        )  # fmt: skip
        blank = draw_overlay(empty, n, window=win, width_px=200, text=False)
        changed = np.any(img != blank, axis=-1).mean()
        assert changed > 0.01, (s.skeleton.name, changed)
        seen.add(skeleton_family(s.skeleton.name))
    assert seen == {"human", "hand", "quadruped"}


def test_3d_render_of_hand_and_quadruped_not_blank():
    from gttdata.cameras import look_at
    from gttdata.preview import _gl
    from gttdata.preview.render import render_view

    try:
        _gl.offscreen_renderer(8, 8)
    except (_gl.RendererUnavailableError, _gl.PreviewDependencyError) as exc:
        pytest.skip(f"no offscreen GL: {exc}")
    K = np.array([[300.0, 0.0, 80.0], [0.0, 300.0, 60.0], [0.0, 0.0, 1.0]])
    for name in ("hand21", "quadruped36"):
        m = generate_skeleton_motion(name, kinds_for_skeleton(name)[0], seed=0, duration_s=0.2, fps_hz=30.0)
        p = m.positions[0]
        centre = p.mean(axis=0)
        eye = centre + np.array([0.0, -4.0, 1.0]) * np.ptp(p, axis=0).max()
        T = look_at(eye, centre)
        img = render_view(p, m.skeleton, K, T, (160, 120), floor=False, flat=True)
        blank = render_view(np.full_like(p, np.nan), m.skeleton, K, T, (160, 120), floor=False, flat=True)
        assert np.any(img != blank, axis=-1).mean() > 0.01, name


def test_mixed_topology_generation_is_bit_identical(mixed_dataset, tmp_path):
    from gttdata.generation import generate_dataset
    from gttdata.manifest import load_manifest

    root, recipe = mixed_dataset
    again = tmp_path / "again"
    generate_dataset(dataclasses.replace(recipe, output_dir=str(again)), progress=False)
    first = {s.path: s.sha256 for s in load_manifest(root).shards}
    assert first == {s.path: s.sha256 for s in load_manifest(again).shards}


def test_schema_1_0_shard_still_reads(mixed_dataset, tmp_path):
    """A shard written before schema 1.1 (no 'skeletons' attribute) reads and indexes as before."""
    import shutil

    import h5py

    from gttdata.manifest import build_manifest
    from gttdata.shards.reader import ShardReader

    root, _ = mixed_dataset
    old = tmp_path / "old"
    shutil.copytree(root, old)
    for path in old.glob("*/shard-*.h5"):
        with h5py.File(path, "r+") as f:
            f.attrs["schema_version"] = "1.0"
            del f.attrs["skeletons"]
            del f.attrs["attrs_sha256"]  # schema 1.2
    shard = next((old / "test").glob("shard-*.h5"))
    with ShardReader(shard) as r:
        assert r.attrs["schema_version"] == "1.0" and "skeletons" not in r.attrs
        assert r.read_sample(0).n_joints > 0
    assert "skeletons" not in build_manifest(old).splits["test"]
