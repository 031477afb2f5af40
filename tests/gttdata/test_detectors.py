"""Detector readers: round trips through every writable layout, property tests, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gttdata.detectors import KEYPOINT_SETS, Keypoints2D, detect_format, read_keypoints, write_keypoints
from gttdata.errors import KeypointFormatError
from gttdata.recording import read_timestamps_csv

_SETTINGS = settings(
    max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


@st.composite
def keypoints(draw, n_joints=None):
    f = draw(st.integers(1, 6))
    j = n_joints or draw(st.integers(1, 8))
    xy = draw(
        st.lists(st.floats(-50, 5000, allow_nan=False, width=64), min_size=f * j * 2, max_size=f * j * 2)
    )
    score = draw(st.lists(st.floats(0.01, 1.0, width=64), min_size=f * j, max_size=f * j))
    missing = draw(st.lists(st.booleans(), min_size=f * j, max_size=f * j))
    frames = np.cumsum(draw(st.lists(st.integers(1, 5), min_size=f, max_size=f))) - 1
    sc = np.where(np.reshape(missing, (f, j)), np.nan, np.reshape(score, (f, j)))
    return Keypoints2D(
        xy=np.reshape(xy, (f, j, 2)),
        score=sc,
        frame=frames,
        joint_names=tuple(f"joint{i}" for i in range(j)),
    )


def _same(a: Keypoints2D, b: Keypoints2D, *, names=True) -> None:
    keep = np.isfinite(a.score).any(axis=1)  # OpenPose/COCO: a frame with nobody is no row at all
    if b.n_frames != a.n_frames:
        a_xy, a_sc, a_fr = a.xy[keep], a.score[keep], a.frame[keep]
    else:
        a_xy, a_sc, a_fr = a.xy, a.score, a.frame
    np.testing.assert_array_equal(b.frame, a_fr)
    np.testing.assert_array_equal(np.isnan(b.score), np.isnan(a_sc))
    np.testing.assert_array_equal(b.xy, a_xy)  # bit-exact: written at full precision
    np.testing.assert_array_equal(b.score, a_sc)
    if names:
        assert b.joint_names == a.joint_names


@_SETTINGS
@given(kp=keypoints())
def test_openpose_round_trip(tmp_path_factory, kp):
    if not np.isfinite(kp.score).any():
        return
    folder = tmp_path_factory.mktemp("op") / "cam1"
    write_keypoints(kp, folder, "openpose")
    back = read_keypoints(folder)
    assert back.fmt == "openpose"
    # OpenPose keeps empty frames as files with no people: rows stay, all missing.
    np.testing.assert_array_equal(back.frame, kp.frame)
    np.testing.assert_array_equal(back.xy, kp.xy)
    np.testing.assert_array_equal(back.score, kp.score)


@_SETTINGS
@given(kp=keypoints())
def test_dlc_csv_round_trip(tmp_path_factory, kp):
    path = tmp_path_factory.mktemp("dlc") / "cam1.csv"
    write_keypoints(kp, path, "dlc")
    back = read_keypoints(path)
    np.testing.assert_array_equal(back.frame, kp.frame)
    np.testing.assert_array_equal(back.xy, kp.xy)
    # DeepLabCut has no "not found": a missing joint reads back as likelihood 0 at NaN coordinates.
    np.testing.assert_array_equal(np.isnan(back.score), np.isnan(kp.score))
    np.testing.assert_array_equal(back.score[np.isfinite(kp.score)], kp.score[np.isfinite(kp.score)])
    assert back.joint_names == kp.joint_names


def test_dlc_h5_round_trip(tmp_path):
    pytest.importorskip("pandas")
    pytest.importorskip("tables")
    rng = np.random.default_rng(0)
    kp = Keypoints2D(
        xy=rng.uniform(0, 1000, (5, 3, 2)), score=rng.uniform(0, 1, (5, 3)), frame=np.arange(5),
        joint_names=("snout", "ear_l", "tail"),
    )  # fmt: skip
    write_keypoints(kp, tmp_path / "cam1.h5", "dlc")
    back = read_keypoints(tmp_path / "cam1.h5")
    _same(kp, back)


def test_dlc_multi_animal_csv_reads_first_individual(tmp_path):
    text = (
        "scorer,S,S,S,S,S,S\nindividuals,a1,a1,a1,a2,a2,a2\nbodyparts,nose,nose,nose,nose,nose,nose\n"
        "coords,x,y,likelihood,x,y,likelihood\n0,1.5,2.5,0.9,7,8,0.4\n1,3,4,0.8,9,10,0.3\n"
    )
    (tmp_path / "c.csv").write_text(text)
    kp = read_keypoints(tmp_path / "c.csv")
    assert kp.joint_names == ("nose",)
    np.testing.assert_array_equal(kp.xy[:, 0], [[1.5, 2.5], [3, 4]])


@_SETTINGS
@given(kp=keypoints(n_joints=17))
def test_coco_round_trip_and_keypoint_set(tmp_path_factory, kp):
    if not np.isfinite(kp.score).any():
        return
    path = tmp_path_factory.mktemp("coco") / "cam1.json"
    write_keypoints(kp, path, "coco")
    back = read_keypoints(path)
    assert back.keypoint_set == "coco17" and back.joint_names == KEYPOINT_SETS["coco17"]
    _same(kp, back, names=False)


def test_mmpose_predictions(tmp_path):
    doc = {
        "meta_info": {"keypoint_id2name": {"0": "nose", "1": "left_eye"}},
        "instance_info": [
            {"frame_id": 3, "instances": [{"keypoints": [[1, 2], [3, 4]], "keypoint_scores": [0.9, 0.0]}]},
            {"frame_id": 5, "instances": [
                {"keypoints": [[5, 6], [7, 8]], "keypoint_scores": [0.2, 0.2]},
                {"keypoints": [[9, 9], [8, 8]], "keypoint_scores": [0.7, 0.8]},
            ]},
        ],
    }  # fmt: skip
    (tmp_path / "p.json").write_text(json.dumps(doc))
    kp = read_keypoints(tmp_path / "p.json")
    assert kp.joint_names == ("nose", "left_eye")
    np.testing.assert_array_equal(kp.frame, [3, 5])
    assert np.isnan(kp.xy[0, 1]).all() and kp.xy[1, 0].tolist() == [9, 9]  # best-scoring instance


@pytest.mark.parametrize(
    "n, name",
    [(17, "coco17"), (18, "coco18"), (26, "halpe26"), (33, "blazepose33"), (68, "halpe68"), (133, "coco133"),
     (135, "body135"), (136, "halpe136")],
)  # fmt: skip
def test_openpose_keypoint_sets(tmp_path, n, name):
    doc = {"people": [{"pose_keypoints_2d": [10.0, 20.0, 0.5] * n}]}
    (tmp_path / "cam_000000000007_keypoints.json").write_text(json.dumps(doc))
    kp = read_keypoints(tmp_path)
    assert kp.keypoint_set == name and kp.n_joints == n and kp.frame.tolist() == [7]


def test_openpose_errors_name_file_and_field(tmp_path):
    (tmp_path / "a_000_keypoints.json").write_text(
        json.dumps({"people": [{"pose_keypoints_2d": [1, 2, 1] * 3}]})
    )
    (tmp_path / "a_001_keypoints.json").write_text(
        json.dumps({"people": [{"pose_keypoints_2d": [1, 2, 1] * 4}]})
    )
    with pytest.raises(KeypointFormatError, match=r"a_001_keypoints.json: field 'pose_keypoints_2d' has 4"):
        read_keypoints(tmp_path)
    (tmp_path / "a_001_keypoints.json").write_text(json.dumps({"people": [{"pose_keypoints_2d": [1, 2]}]}))
    with pytest.raises(
        KeypointFormatError, match=r"a_001_keypoints.json: field 'people\[0\].pose_keypoints_2d'"
    ):
        read_keypoints(tmp_path)
    with pytest.raises(KeypointFormatError, match="suffix"):
        detect_format(tmp_path / "x.txt")
    with pytest.raises(FileNotFoundError):
        read_keypoints(tmp_path / "missing_cam")


def test_dlc_bad_header(tmp_path):
    (tmp_path / "c.csv").write_text("scorer,S,S\ncoords,x,y\n0,1,2\n")
    with pytest.raises(KeypointFormatError, match=r"c.csv: DeepLabCut header row 'bodyparts' is missing"):
        read_keypoints(tmp_path / "c.csv")


@_SETTINGS
@given(
    dt=st.lists(st.floats(1e-4, 1.0), min_size=1, max_size=30),
    t0=st.floats(0, 100),
    style=st.sampled_from(["frame", "plain", "header"]),
)
def test_timestamps_csv_ffprobe_styles(tmp_path_factory, dt, t0, style):
    t = t0 + np.concatenate([[0.0], np.cumsum(dt)])
    t = np.unique(np.round(t, 6))
    lines = {
        "frame": [f"frame,{x:.6f}" for x in t],
        "plain": [f"{x:.6f}" for x in t],
        "header": ["pts_time"] + [f"{x:.6f}" for x in t],
    }[style]
    path = tmp_path_factory.mktemp("ts") / "t.csv"
    path.write_text("\n".join(lines) + "\n")
    np.testing.assert_allclose(read_timestamps_csv(path), t, atol=1e-12)


def test_timestamps_csv_errors(tmp_path):
    (tmp_path / "t.csv").write_text("frame,0.0\nframe,N/A\n")
    with pytest.raises(KeypointFormatError, match=r"t.csv: line 2: frame time must be a number, found 'N/A'"):
        read_timestamps_csv(tmp_path / "t.csv")
    (tmp_path / "t.csv").write_text("frame,0.1\nframe,0.05\n")
    with pytest.raises(KeypointFormatError, match="must increase"):
        read_timestamps_csv(tmp_path / "t.csv")


def test_sleap_reader(tmp_path):
    sio = pytest.importorskip("sleap_io")
    sk = sio.Skeleton(["head", "tail"])
    video = sio.Video(filename="cam1.mp4")
    frames = [
        sio.LabeledFrame(
            video=video,
            frame_idx=k,
            instances=[
                sio.PredictedInstance.from_numpy(
                    np.array([[k, 2.0 * k], [3.0, 4.0]]),
                    skeleton=sk,
                    point_scores=np.array([0.9, 0.4]),
                    score=1,
                )
            ],
        )
        for k in (0, 2, 3)
    ]
    sio.save_slp(sio.Labels(labeled_frames=frames, videos=[video], skeletons=[sk]), str(tmp_path / "c.slp"))
    kp = read_keypoints(tmp_path / "c.slp")
    assert kp.joint_names == ("head", "tail") and kp.frame.tolist() == [0, 2, 3]
    np.testing.assert_allclose(kp.xy[:, 0], [[0, 0], [2, 4], [3, 6]])
    np.testing.assert_allclose(kp.score[:, 1], 0.4)


def test_openpose_25_joints_are_never_guessed(tmp_path):
    """BODY_25 and BODY_25B share 25 points: without a named skeleton the recording names both."""
    from gttdata.recording import _skeleton

    doc = {"people": [{"pose_keypoints_2d": [10.0, 20.0, 0.5] * 25}]}
    (tmp_path / "cam_000000000007_keypoints.json").write_text(json.dumps(doc))
    kp = read_keypoints(tmp_path)
    assert kp.keypoint_set == "" and kp.n_joints == 25
    with pytest.raises(KeypointFormatError, match="body25 and body25b"):
        _skeleton(kp.joint_names, None, kp.keypoint_set)
    assert _skeleton(kp.joint_names, "BODY_25B", "").joint_names[17:19] == ("Neck", "Head")
    assert _skeleton(kp.joint_names, "body25", "").joint_names[8] == "MidHip"
    assert _skeleton(kp.joint_names[:18], "COCO", "").name == "coco18"  # Pose2Sim's model names too
    with pytest.raises(KeypointFormatError, match="unknown skeleton 'BODY_99'"):
        _skeleton(kp.joint_names, "BODY_99", "")


def test_openpose_empty_person_is_nobody(tmp_path):
    """Pose2Sim's pose-associated output writes ``"people": [{}]`` where the person was not found."""
    (tmp_path / "c_000000000000_keypoints.json").write_text(json.dumps({"people": [{}]}))
    (tmp_path / "c_000000000001_keypoints.json").write_text(
        json.dumps({"people": [{"pose_keypoints_2d": [1.0, 2.0, 0.9] * 17}]})
    )
    kp = read_keypoints(tmp_path)
    assert kp.frame.tolist() == [0, 1] and np.isnan(kp.xy[0]).all() and kp.xy[1, 0].tolist() == [1, 2]
