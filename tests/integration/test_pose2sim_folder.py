"""A Pose2Sim-like trial folder reconstructs with no other argument into an OpenSim-ready TRC.

The session is simulated (tests/integration/_pose2sim_trial.py): Config.toml (frame rate, BODY_25B), a
calibration whose cameras are ``cam_01``... beside folders ``cam01_json``..., frames with ``"people": [{}]``.
An unsynchronized copy (cameras started 7, 3 and 12 frames late) must give the same motion and offsets
that differ by exactly those frames.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.skeletons_detectors import BODY25B_JOINTS
from gttnet.cli import main
from gttnet.io.motion_files import read_trc
from tests.integration._pose2sim_trial import FPS, body25b_walk, write_session

pytestmark = pytest.mark.integration

DROP = (0, 7, 3, 12)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    root = tmp_path_factory.mktemp("p2s")
    trial, _, _ = write_session(root / "synced")
    late, _, _ = write_session(root / "late", drop=DROP)
    return trial, late


def _run(*args):
    res = CliRunner().invoke(main, ["reconstruct", *map(str, args)])
    assert res.exit_code == 0, res.output
    return res


def test_trial_folder_alone_gives_an_opensim_trc(sessions, tmp_path):
    trial, _ = sessions
    out = tmp_path / "new" / "r.trc"  # --out creates its folder
    _run(trial, "--out", out)
    lines = out.read_text().splitlines()
    assert lines[0].startswith("PathFileType\t4\t(X/Y/Z)\t")
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t"), strict=True))
    names, t, P, units = read_trc(out)
    assert names == BODY25B_JOINTS and units == "m"
    assert float(header["DataRate"]) == FPS and float(header["CameraRate"]) == FPS
    assert int(header["NumFrames"]) == t.shape[0] == P.shape[0] and int(header["NumMarkers"]) == 25
    assert [int(r.split("\t")[0]) for r in lines[6:]] == list(range(1, t.shape[0] + 1))
    np.testing.assert_allclose(np.diff(t), 1 / FPS, atol=1e-9)  # one row per frame, no repeated time
    head, ankle = names.index("Head"), names.index("LAnkle")
    assert np.nanmedian(P[:, head, 1]) - np.nanmedian(P[:, ankle, 1]) > 1.2  # Y up
    # Against the simulated walk at the TRC's times (cam_01's clock: frame k at k / 30 s).
    X = body25b_walk()[np.rint(t * 120).astype(int)][..., [1, 2, 0]]
    err = np.linalg.norm(P - X, axis=-1)
    assert np.nanmedian(err) < 0.02, np.nanmedian(err)


def test_unsynchronized_copy_gives_the_same_motion_and_its_offsets(sessions, tmp_path):
    trial, late = sessions
    got = {}
    for name, folder in (("synced", trial), ("late", late)):
        res = _run(folder, "--out", tmp_path / f"{name}.trc", "--json")
        got[name] = (json.loads(res.stdout.strip().splitlines()[-1]), read_trc(tmp_path / f"{name}.trc"))
    offsets = {k: np.array(list(v[0]["clock_offsets_s"].values())) for k, v in got.items()}
    assert list(got["late"][0]["clock_offsets_s"]) == ["cam_01", "cam_02", "cam_03", "cam_04"]
    shift = (offsets["late"] - offsets["synced"]) * FPS
    np.testing.assert_array_less(np.abs(shift - np.array(DROP)), 0.25)
    (_, ta, A, _), (_, tb, B, _) = got["synced"][1], got["late"][1]
    n = min(ta.shape[0], tb.shape[0])
    np.testing.assert_allclose(ta[:n], tb[:n], atol=1e-6)
    assert np.nanmedian(np.linalg.norm(A[:n] - B[:n], axis=-1)) < 0.010


def test_filter_up_and_skeleton_options(sessions, tmp_path):
    trial, _ = sessions
    _run(trial, "--out", tmp_path / "z.trc", "--up", "z", "--filter", "butterworth:6")
    _run(trial, "--out", tmp_path / "y.trc")
    _, _, Z, _ = read_trc(tmp_path / "z.trc")
    _, _, Y, _ = read_trc(tmp_path / "y.trc")
    d = np.linalg.norm(Z[..., [1, 2, 0]] - Y, axis=-1)
    assert 0 < np.nanmedian(d) < 0.01  # same motion, smoothed, in the other frame
    res = CliRunner().invoke(
        main, ["reconstruct", str(trial), "--skeleton", "BODY_25", "--out", str(tmp_path / "b.trc")]
    )
    assert res.exit_code == 0, res.output
    assert read_trc(tmp_path / "b.trc")[0][8] == "CHip"  # told BODY_25: its names, Pose2Sim's CHip
    res = CliRunner().invoke(
        main, ["reconstruct", str(trial), "--fps", "30", "30", "--out", str(tmp_path / "c.trc")]
    )
    assert res.exit_code == 1 and "--fps 25,30,60" in res.output and len(res.output.strip().splitlines()) == 1


def test_sync_takes_the_folder_or_calibration_and_keypoints(sessions, tmp_path):
    """``gttnet sync`` reads recordings as ``reconstruct`` does, with the same ``--fps`` forms."""
    _, late = sessions
    res = CliRunner().invoke(main, ["sync", str(late), "--out", str(tmp_path / "a.json"), "--json"])
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout.strip().splitlines()[-1])["cameras"]
    assert [r["name"] for r in rows] == ["cam_01", "cam_02", "cam_03", "cam_04"]
    a = np.array([r["offset_s"] for r in rows])
    session = late.parents[1]
    sources = [f"cam_{v:02d}={late / 'pose' / f'cam{v:02d}_json'}" for v in range(1, 5)]
    args = [
        "--calibration",
        str(session / "calibration" / "Calib_scene.toml"),
        "--keypoints",
        *sources,
        "--skeleton",
        "BODY_25B",
    ]
    for fps in (
        ["--fps", "30,30,30,30"],
        ["--fps", "30"],
        ["--fps", "cam_01=30,cam_02=30,cam_03=30,cam_04=30"],
    ):
        out = tmp_path / f"b{len(fps[1])}.json"
        res = CliRunner().invoke(main, ["sync", *args, *fps, "--out", str(out), "--json"])
        assert res.exit_code == 0, res.output
        b = np.array([r["offset_s"] for r in json.loads(res.stdout.strip().splitlines()[-1])["cameras"]])
        np.testing.assert_allclose(b - b[0], a - a[0], atol=1e-9)
    res = CliRunner().invoke(main, ["sync", *args, "--fps", "30,30", "--out", str(tmp_path / "c.json")])
    assert res.exit_code == 1 and "one per camera (4" in res.output


def test_human_summary_names_cameras_plainly(sessions, tmp_path):
    _, late = sessions
    res = _run(late, "--method", "sync", "--out", tmp_path / "h.trc")
    line = res.stdout.strip().splitlines()[-1]
    assert "clock_offsets_s=cam_01:0.0,cam_02:" in line and "{" not in line and "'" not in line


def test_retimed_keypoints_are_synchronized_openpose_folders(sessions, tmp_path):
    """The late-started copy's detections re-timed onto the common clock agree with the synced trial's."""
    from gttdata.detectors import read_keypoints

    _, late = sessions
    out = tmp_path / "retimed"
    _run(late, "--out", tmp_path / "r.trc", "--export-keypoints", out)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["cam_01_json", "cam_02_json", "cam_03_json", "cam_04_json"]
    frames = {n: read_keypoints(out / n) for n in names}
    assert len({kp.n_frames for kp in frames.values()}) == 1  # one common frame count
    # Common frame k is at k / 30 s on cam_01's clock (offset 0): the walk's 120 Hz sample 4 k, projected.
    from gttdata.calibration import load_calibration

    rig, _ = load_calibration(late.parents[1] / "calibration" / "Calib_scene.toml")
    X = body25b_walk()
    for v, name in enumerate(names):
        kp = frames[name]
        idx = 4 * kp.frame[4 * kp.frame < X.shape[0]]
        px, _ = rig.cameras[v].project(X[idx])
        d = np.linalg.norm(kp.xy[: idx.size] - px, axis=-1)
        assert np.nanmedian(d) < 1.5, (name, np.nanmedian(d))  # 1 px detection noise, re-timed
        assert np.isfinite(d).mean() > 0.7  # cameras started up to 12 of 121 frames late lack the first ones
    res = CliRunner().invoke(main, ["reconstruct", str(late), "--export-keypoints", str(out)])
    assert res.exit_code == 1 and "--overwrite" in res.output


def test_keypoint_folders_match_calibration_cameras_by_number(sessions, tmp_path):
    """``--keypoints .../cam01_json`` (camera ``cam01``) is the calibration's ``cam_01``."""
    trial, _ = sessions
    cal = trial.parents[1] / "calibration" / "Calib_scene.toml"
    folders = [trial / "pose" / f"cam{v:02d}_json" for v in (3, 1, 2, 4)]
    res = _run(
        "--calibration", cal, "--keypoints", *folders, "--fps", "30", "--skeleton", "body25b", "--method", "sync",
        "--out", tmp_path / "r.trc", "--json",
    )  # fmt: skip
    offsets = json.loads(res.stdout.strip().splitlines()[-1])["clock_offsets_s"]
    assert list(offsets) == ["cam_03", "cam_01", "cam_02", "cam_04"]


def test_anipose_session_folder(tmp_path):
    """An anipose session (calibration/calibration.toml, pose-2d/<trial>-cam<X>.csv, the project's cam_regex)."""
    import tomli_w

    from gttdata.calibration import load_calibration, save_calibration
    from gttdata.cameras import CameraRig
    from gttdata.export import export_capture
    from tests.fixtures.scenes import make_scene

    sample = make_scene(n_cameras=3, n_joints=6, frames_per_camera=12, sigma_px=0.5, seed=2)
    export_capture(sample, tmp_path / "exp", fmt="dlc")
    project = tmp_path / "project"
    session = project / "session1"
    (session / "calibration").mkdir(parents=True)
    (session / "pose-2d").mkdir()
    (project / "config.toml").write_text(tomli_w.dumps({"triangulation": {"cam_regex": "-cam([A-Z])"}}))
    rig, _ = load_calibration(tmp_path / "exp" / "calibration.toml")
    letters = "ABC"
    rig = CameraRig(
        tuple(c.__class__(**{**c.__dict__, "name": letters[v]}) for v, c in enumerate(rig.cameras))
    )
    save_calibration(rig, session / "calibration" / "calibration.toml")
    for v in range(3):
        (tmp_path / "exp" / f"cam_{v}.csv").rename(session / "pose-2d" / f"trial-cam{letters[v]}.csv")
    res = _run(session, "--fps", "30", "--method", "sync", "--out", tmp_path / "r.h5", "--json")
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["n_cameras"] == 3 and list(summary["clock_offsets_s"]) == ["A", "B", "C"]
    res = CliRunner().invoke(
        main, ["reconstruct", str(session), "--method", "dloe", "--out", str(tmp_path / "u.trc")]
    )
    assert res.exit_code == 0  # no clock recovered: the TRC keeps one row per image, and a warning says so
    assert "warning:" in res.output and "no clock" in res.output
