"""Tests for the skeleton registry, the detector keypoint sets and the CMU-31 derivation maps."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gttdata.mocap.procedural import generate_motion
from gttdata.skeleton import CMU31_JOINTS, Skeleton
from gttdata.skeletons import (
    CMU31_DERIVATIONS,
    FAMILIES,
    available_skeletons,
    derivable_from_cmu31,
    derive_from_cmu31,
    derive_positions,
    get_skeleton,
    skeleton_family,
)

# Canonical joint counts and the first and last joint of each tool's order.
CANONICAL = {
    "coco17": (17, "nose", "right_ankle"),
    "h36m17": (17, "pelvis", "right_wrist"),
    "body25": (25, "Nose", "RHeel"),
    "halpe26": (26, "nose", "right_heel"),
    "hand21": (21, "wrist", "pinky4"),
    "cmu31": (31, "root", "rthumb"),
}

# Joints with a left/right counterpart (everything off the midline).
SIDED = {"coco17": 16, "h36m17": 12, "body25": 22, "halpe26": 22, "hand21": 0, "cmu31": 24}


def _unsided(name: str) -> str:
    for prefix in ("left", "right", "L", "R", "l", "r"):
        if name.startswith(prefix):
            return name[len(prefix) :]
    return name


@pytest.fixture(scope="module")
def walk():
    return generate_motion("walk", seed=3, duration_s=1.0, fps_hz=60.0)


@pytest.mark.parametrize("name", sorted(CANONICAL))
def test_registered_topology_canonical_order(name):
    sk = get_skeleton(name)
    n, first, last = CANONICAL[name]
    assert sk.name == name and sk.n_joints == n
    assert (sk.joint_names[0], sk.joint_names[-1]) == (first, last)
    assert skeleton_family(name) in FAMILIES
    assert name in available_skeletons(skeleton_family(name))


@pytest.mark.parametrize("name", sorted(CANONICAL))
def test_every_joint_has_a_bone_and_mirror_pairs_sides(name):
    sk = get_skeleton(name)
    assert len(sk.bones) == sk.n_joints - 1  # one tree: every joint reachable
    order = sk.topological_order
    assert sorted(order) == list(range(sk.n_joints))
    pos = {j: k for k, j in enumerate(order)}
    assert all(pos[p] < pos[c] for c, p in sk.bones)
    sided = [i for i in range(sk.n_joints) if sk.mirror[i] != i]
    assert len(sided) == SIDED[name]
    for i in sided:  # a pair differs only in its side prefix
        a, b = sk.joint_names[i], sk.joint_names[sk.mirror[i]]
        assert a != b and _unsided(a) == _unsided(b)


def test_coco_extra_limbs_drawn_but_not_tree_bones():
    sk = get_skeleton("coco17")
    assert sk.limbs.shape == (19, 2)  # COCO's 19 limbs
    assert len(sk.bones) == 16


def test_lookup_ignores_case_and_separators_and_names_unknown():
    assert get_skeleton("COCO-17") == get_skeleton("coco17")
    assert skeleton_family("not-a-skeleton") is None
    with pytest.raises(KeyError, match="coco17"):
        get_skeleton("coco19")


@pytest.mark.parametrize("target", derivable_from_cmu31())
def test_derivation_map_complete(target):
    sk = get_skeleton(target)
    rules = CMU31_DERIVATIONS[target]
    assert list(rules) == list(sk.joint_names) or set(rules) == set(sk.joint_names)
    for name, rule in rules.items():
        assert rule.startswith(("virtual", "mean(")) or rule in CMU31_JOINTS, (name, rule)


@pytest.mark.parametrize("target", derivable_from_cmu31())
def test_derived_motion_copies_cmu_joints_and_is_mirror_equivariant(walk, target):
    d = derive_from_cmu31(walk, target)
    assert d.positions.shape == (walk.n_frames, get_skeleton(target).n_joints, 3)
    assert np.all(np.isfinite(d.positions))
    for j, n in enumerate(d.skeleton.joint_names):
        rule = CMU31_DERIVATIONS[target][n]
        if rule in CMU31_JOINTS:
            np.testing.assert_array_equal(d.positions[:, j], walk.positions[:, CMU31_JOINTS.index(rule)])
    # Deriving the mirrored motion equals mirroring the derived one: left eye stays left, etc.
    np.testing.assert_allclose(
        derive_from_cmu31(walk.mirror(), target).positions, d.mirror().positions, atol=1e-12
    )


def test_virtual_face_points_rigid_on_the_head_and_in_front(walk):
    d = derive_from_cmu31(walk, "coco17")
    head = walk.positions[:, CMU31_JOINTS.index("head")]
    nose = d.positions[:, 0]
    dist = np.linalg.norm(nose - head, axis=-1)
    np.testing.assert_allclose(dist, dist[0], rtol=1e-9)
    # The nose is ahead of the head in the direction of travel (walk: forward motion).
    travel = walk.positions[-1, 0, :2] - walk.positions[0, 0, :2]
    assert float(np.mean((nose - head)[:, :2] @ travel)) > 0
    # Eyes are between the ears, the left eye on the left ear's side.
    le, re, lear, rear = (d.positions[:, i] for i in (1, 2, 3, 4))
    assert np.all(np.linalg.norm(le - lear, axis=-1) < np.linalg.norm(le - rear, axis=-1))


def test_virtual_foot_points_near_the_floor_when_standing(walk):
    d = derive_from_cmu31(walk, "body25")
    z = {n: d.positions[:, d.skeleton.index(n), 2] for n in ("LBigToe", "LHeel", "LAnkle")}
    assert z["LBigToe"].min() < 0.03 and z["LHeel"].min() < 0.05
    assert np.median(z["LHeel"]) < np.median(z["LAnkle"])


def test_derive_rejects_non_cmu_input_and_shapes(walk):
    coco = derive_from_cmu31(walk, "coco17")
    with pytest.raises(ValueError, match="CMU-31"):
        derive_from_cmu31(coco, "body25")
    with pytest.raises(ValueError, match=r"\(\.\.\., 31, 3\)"):
        derive_positions(np.zeros((4, 17, 3)), "coco17")
    with pytest.raises(KeyError, match="cannot be derived"):
        derive_positions(np.zeros((31, 3)), "hand21")


def test_skeleton_with_extra_bones_dict_round_trip():
    sk = get_skeleton("coco17")
    back = Skeleton.from_dict(json.loads(json.dumps(sk.to_dict())))
    assert back == sk and back.extra_bones == sk.extra_bones


def test_scale_bones_on_a_tree_whose_parents_follow_children(walk):
    d = derive_from_cmu31(walk, "halpe26")  # root 'hip' is joint 19: parents need not precede
    s = d.scale_bones(2.0)
    np.testing.assert_allclose(s.bone_lengths(), 2.0 * d.bone_lengths(), rtol=1e-9)
    np.testing.assert_array_equal(s.positions[:, 19], d.positions[:, 19])


def test_docs_list_every_registered_skeleton_and_rule():
    from pathlib import Path

    text = (Path(__file__).parents[2] / "docs" / "SKELETONS.md").read_text()
    for name in available_skeletons():
        assert f"`{name}`" in text
    for target, rules in CMU31_DERIVATIONS.items():
        if target != "cmu31":
            for joint, rule in rules.items():
                assert f"| `{joint}` | {rule} |" in text, (target, joint)


@pytest.mark.parametrize("suffix", [".npz", ".h5"])
def test_derived_motion_file_round_trip_keeps_the_skeleton(walk, tmp_path, suffix):
    from gttdata.mocap import load_motion
    from gttdata.mocap.arrays import save_motion

    coco = derive_from_cmu31(walk, "coco17")
    back = load_motion(save_motion(coco, tmp_path / f"coco{suffix}"))
    assert back.skeleton == coco.skeleton and back.skeleton.extra_bones == coco.skeleton.extra_bones
    np.testing.assert_array_equal(back.positions, coco.positions)
