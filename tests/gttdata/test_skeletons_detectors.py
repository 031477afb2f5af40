"""Detector keypoint sets: counts, joint names at the indices Pose2Sim's skeletons give them, trees."""

from __future__ import annotations

import pytest

from gttdata.skeletons import get_skeleton
from gttdata.skeletons_detectors import POSE2SIM_MODELS, pose2sim_model, trc_marker_names

# name -> (joint count, {index: name}) at indices Pose2Sim's skeletons.py (or the tool's docs) fix.
KNOWN = {
    "body25b": (25, {0: "Nose", 5: "LShoulder", 12: "RHip", 17: "Neck", 18: "Head", 19: "LBigToe", 24: "RHeel"}),
    "body25": (25, {1: "Neck", 8: "MidHip", 9: "RHip", 19: "LBigToe", 24: "RHeel"}),
    "body135": (135, {17: "Neck", 18: "Head", 27: "LThumb", 30: "LIndex", 42: "LPinky", 48: "RThumb",
                      51: "RIndex", 63: "RPinky"}),
    "coco18": (18, {1: "Neck", 2: "RShoulder", 8: "RHip", 11: "LHip", 14: "REye", 17: "LEar"}),
    "coco17": (17, {0: "nose", 5: "left_shoulder", 16: "right_ankle"}),
    "halpe26": (26, {17: "head", 18: "neck", 19: "hip", 20: "left_big_toe", 25: "right_heel"}),
    "halpe68": (68, {19: "Hip", 28: "LThumb", 31: "LIndex", 43: "LPinky", 49: "RThumb", 52: "RIndex",
                     64: "RPinky"}),
    "halpe136": (136, {18: "Neck", 26: "Jaw1", 96: "LThumb", 99: "LIndex", 111: "LPinky", 117: "RThumb",
                       120: "RIndex", 132: "RPinky"}),
    "coco133": (133, {17: "LBigToe", 22: "RHeel", 23: "Jaw1", 39: "Jaw17", 40: "EyebrowR1", 50: "Nose1",
                      59: "REye1", 71: "Mouth1", 90: "Mouth20", 92: "LThumb1", 93: "LThumb", 96: "LIndex",
                      108: "LPinky", 113: "RThumb1", 114: "RThumb", 117: "RIndex", 129: "RPinky"}),
    "blazepose33": (33, {0: "nose", 2: "left_eye", 5: "right_eye", 11: "left_shoulder", 23: "left_hip",
                         25: "left_knee", 29: "left_heel", 31: "left_foot_index", 32: "right_foot_index"}),
    "hand21": (21, {0: "wrist", 1: "thumb1", 5: "index1", 20: "pinky4"}),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(KNOWN))
def test_counts_and_names_at_known_indices(name):
    n, at = KNOWN[name]
    sk = get_skeleton(name)
    assert sk.n_joints == n
    for i, joint in at.items():
        assert sk.joint_names[i] == joint, (name, i)
    assert len(sk.bones) == n - 1  # one tree: every joint but the root has a bone


@pytest.mark.parametrize(
    "name, at",
    [
        ("body25", {8: "CHip", 1: "Neck"}),
        ("coco17", {0: "Nose", 5: "LShoulder", 16: "RAnkle"}),
        ("halpe26", {17: "Head", 18: "Neck", 19: "Hip", 20: "LBigToe", 23: "RSmallToe"}),
        ("blazepose33", {25: "LKnee", 29: "LHeel", 31: "LBigToe", 32: "RBigToe"}),
        ("hand21", {0: "RWrist", 1: "RThumb1", 20: "RPinky4"}),
        ("body25b", {17: "Neck", 18: "Head"}),
    ],
)
def test_trc_marker_names_are_pose2sims(name, at):
    names = trc_marker_names(get_skeleton(name))
    assert len(set(names)) == len(names)
    for i, joint in at.items():
        assert names[i] == joint


def test_pose2sim_models_map_to_registered_skeletons():
    for model, name in POSE2SIM_MODELS.items():
        assert get_skeleton(name).name == name, model
    assert pose2sim_model("body_25b") == "body25b" and pose2sim_model("Coco") == "coco18"
    with pytest.raises(KeyError, match="BODY_25B"):
        pose2sim_model("BODY_99")


def test_left_right_points_mirror():
    sk = get_skeleton("coco133")
    idx = {n: i for i, n in enumerate(sk.joint_names)}
    assert sk.mirror[idx["LThumb"]] == idx["RThumb"] and sk.mirror[idx["LHandRoot"]] == idx["RHandRoot"]
    assert sk.mirror[idx["Jaw1"]] == idx["Jaw1"]
