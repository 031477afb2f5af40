"""Tests for the Skeleton value object and the CMU-31 topology."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gttdata.errors import MotionFormatError
from gttdata.skeleton import CMU31_BVH_ALIASES, CMU31_JOINTS, Skeleton, cmu31, load_skeleton


def test_cmu31_smoke():
    sk = cmu31()
    assert sk.n_joints == 31
    assert sk.joint_names == CMU31_JOINTS
    assert sk.parents[0] == -1
    assert sum(p == -1 for p in sk.parents) == 1


def test_cmu31_bones_shape_and_parent_order():
    sk = cmu31()
    bones = sk.bones
    assert bones.shape == (30, 2)
    assert bones.dtype == np.int64
    assert np.all(bones[:, 1] < bones[:, 0])


@pytest.mark.parametrize(
    ("left", "right"),
    [("lfemur", "rfemur"), ("lhipjoint", "rhipjoint"), ("lthumb", "rthumb"), ("lclavicle", "rclavicle")],
)
def test_cmu31_mirror_pairs(left, right):
    sk = cmu31()
    i, j = sk.index(left), sk.index(right)
    assert sk.mirror[i] == j and sk.mirror[j] == i


@pytest.mark.parametrize("name", ["root", "lowerback", "thorax", "head", "upperneck"])
def test_cmu31_midline_joints_mirror_to_themselves(name):
    sk = cmu31()
    assert sk.mirror[sk.index(name)] == sk.index(name)


def test_flip_index_is_involution():
    f = cmu31().flip_index()
    assert f.shape == (31,)
    np.testing.assert_array_equal(f[f], np.arange(31))


def test_aliases_resolve_to_asf_order():
    sk = cmu31()
    for i, alias in enumerate(CMU31_BVH_ALIASES):
        assert sk.index(alias) == i
    assert sk.index("LeftUpLeg") == sk.index("lfemur")


def test_index_unknown_joint_names_it():
    with pytest.raises(KeyError, match="nosuchjoint"):
        cmu31().index("nosuchjoint")


def test_mirror_derived_from_left_right_names():
    sk = Skeleton("t", ("hips", "LeftLeg", "RightLeg", "spine"), (-1, 0, 0, 0))
    assert sk.mirror == (0, 2, 1, 3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"joint_names": (), "parents": ()}, "non-empty"),
        ({"joint_names": ("a", "b"), "parents": (-1,)}, "length 2"),
        ({"joint_names": ("a", "b"), "parents": (-1, 1)}, "another joint index"),
        ({"joint_names": ("a", "b"), "parents": (-1, 2)}, "another joint index"),
        ({"joint_names": ("a", "b", "c"), "parents": (-1, 2, 1)}, "cycle"),
        ({"joint_names": ("a", "b"), "parents": (-1, 0), "extra_bones": ((0, 0),)}, "extra_bones"),
        ({"joint_names": ("a", "a"), "parents": (-1, 0)}, "unique"),
        ({"joint_names": ("a", "b"), "parents": (-1, 0), "mirror": (1, 1)}, "involution"),
    ],
)
def test_invalid_skeleton_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Skeleton(name="bad", **kwargs)


def test_dict_round_trip():
    sk = cmu31()
    back = Skeleton.from_dict(json.loads(json.dumps(sk.to_dict())))
    assert back == sk


def test_from_dict_missing_field_names_it():
    with pytest.raises(MotionFormatError, match="'parents'"):
        Skeleton.from_dict({"name": "x", "joint_names": ["a"]})


def test_load_skeleton_file(tmp_path):
    p = tmp_path / "sk.json"
    p.write_text(json.dumps(cmu31().to_dict()))
    assert load_skeleton(p) == cmu31()


def test_load_skeleton_bad_json_names_line(tmp_path):
    p = tmp_path / "sk.json"
    p.write_text('{\n"name": "x",\n oops}')
    with pytest.raises(MotionFormatError, match="line 3"):
        load_skeleton(p)


def test_load_skeleton_missing_file(tmp_path):
    with pytest.raises(MotionFormatError, match="not found"):
        load_skeleton(tmp_path / "none.json")
