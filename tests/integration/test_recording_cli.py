"""End to end: ``gttdata export`` -> ``gttnet reconstruct`` of the recording -> TRC/C3D/CSV/H5, and errors."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.cli import main as gttdata_main
from gttnet.cli import main as gttnet_main
from gttnet.io.motion_files import read_c3d_points, read_motion_csv, read_trc
from gttnet.io.output import read_reconstruction

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def shard(tmp_path_factory):
    from gttdata.shards.writer import ShardWriter
    from tests.fixtures.scenes import make_scene

    sample = make_scene(n_cameras=3, n_joints=6, frames_per_camera=10, sigma_px=1.0, missing=0.1, seed=5)
    d = tmp_path_factory.mktemp("shard")
    with ShardWriter(d / "shards", split="test") as w:
        w.write(sample)
    return sorted((d / "shards").glob("*.h5"))[0]


def _export(shard, out, *args):
    res = CliRunner().invoke(gttdata_main, ["export", str(shard), "--out", str(out), *args])
    assert res.exit_code == 0, res.output
    return out / "project.toml"


def _reconstruct(*args):
    return CliRunner().invoke(gttnet_main, ["reconstruct", *map(str, args)])


def _json(res) -> dict:
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_round_trip_trc_c3d_csv_equal_h5_and_shard_mpjpe(shard, tmp_path):
    project = _export(shard, tmp_path / "rec", "--format", "openpose", "--units", "mm")
    outs = [tmp_path / f"r.{s}" for s in ("h5", "trc", "c3d", "csv")]
    got = _json(_reconstruct(project, "--method", "dloe", *[a for o in outs for a in ("--out", o)], "--json"))
    ref = _json(_reconstruct(shard, "--method", "dloe", "--sequencing", "partial", "--json"))
    assert got["sequencing"] == "partial"
    assert abs(got["mpjpe_mm"] - ref["mpjpe_mm"]) <= 0.01 * ref["mpjpe_mm"]
    arrays, attrs = read_reconstruction(outs[0])
    X = arrays["points3d"][arrays["time_order"]]
    names, t, P, units = read_trc(outs[1])
    assert units == "m" and len(names) == 6 and P.shape == X.shape
    Y = X[..., [1, 2, 0]]  # TRC is Y up: X, Y, Z = world y, z, x
    assert np.nanmax(np.abs(P - Y)) < 1e-6 and np.array_equal(np.isnan(P), np.isnan(X))
    labels, _, C, c3d_units = read_c3d_points(outs[2])
    assert c3d_units == "m" and np.nanmax(np.abs(C - X)) < 1e-6
    _, t_csv, cams, frames, Q = read_motion_csv(outs[3])
    assert np.nanmax(np.abs(Q - X)) < 1e-6
    names_by_id = json.loads(attrs["camera_names"])
    assert cams == [names_by_id[c] for c in arrays["cam_id"][arrays["time_order"]]]
    np.testing.assert_array_equal(frames, arrays["frame"][arrays["time_order"]])
    # Untimed (per-camera clocks, no clock recovery): each camera's frames still run forward in time.
    for cam in set(cams):
        f = frames[np.array(cams) == cam]
        assert np.mean(np.diff(f) > 0) > 0.5


def test_shared_clock_full_sequencing_times_and_resample(shard, tmp_path):
    from gttdata.shards.reader import ShardReader

    project = _export(shard, tmp_path / "rec", "--shared-clock", "--format", "dlc")
    trc, res_trc, csv = tmp_path / "r.trc", tmp_path / "u.trc", tmp_path / "r.csv"
    got = _json(_reconstruct(project, "--method", "hpf", "--out", trc, "--out", csv, "--json"))
    assert got["sequencing"] == "full"
    # Without confidence weights the export is the shard's capture exactly.
    unweighted = _json(_reconstruct(project, "--method", "hpf", "--no-weights", "--json"))
    ref = _json(_reconstruct(shard, "--method", "hpf", "--sequencing", "full", "--json"))
    assert unweighted["mpjpe_mm"] == pytest.approx(ref["mpjpe_mm"], rel=1e-6)
    with ShardReader(shard) as r:
        truth = r.read_sample(0)
    t = read_motion_csv(csv)[1]  # the .csv keeps one row per image, at its time
    np.testing.assert_allclose(t, np.sort(truth.timestamp_s), atol=1e-8)
    # The .trc has one row per frame at the fastest camera's rate, as OpenSim expects.
    rate = max(truth.meta["capture"]["fps_hz"]) if "capture" in truth.meta else 30.0
    _, tt, _, _ = read_trc(trc)
    np.testing.assert_allclose(np.diff(tt), 1.0 / rate, atol=1e-8)
    header = dict(zip(*[ln.split("\t") for ln in trc.read_text().splitlines()[1:3]], strict=False))
    assert float(header["DataRate"]) == pytest.approx(rate) and int(header["NumFrames"]) == tt.shape[0]
    _json(_reconstruct(project, "--method", "hpf", "--out", res_trc, "--resample", "50", "--json"))
    _, tu, Pu, _ = read_trc(res_trc)
    np.testing.assert_allclose(np.diff(tu), 0.02, atol=1e-8)
    assert np.isfinite(Pu).mean() > 0.8


def test_calibration_units_mm_and_m_agree(shard, tmp_path):
    outs = []
    for units in ("m", "mm"):
        project = _export(shard, tmp_path / units, "--units", units)
        outs.append(tmp_path / f"{units}.h5")
        _json(_reconstruct(project, "--method", "pseudo", "--out", outs[-1], "--json"))
    a, b = (read_reconstruction(o)[0]["points3d"] for o in outs)
    assert np.nanmax(np.abs(a - b)) < 1e-9


def test_keypoints_and_fps_options(shard, tmp_path):
    _export(shard, tmp_path / "rec")
    rec = tmp_path / "rec"
    res = _reconstruct(
        "--calibration", rec / "calibration.toml", "--keypoints", rec / "cam_0", rec / "cam_1", rec / "cam_2",
        "--fps", "30", "--method", "pseudo", "--out", tmp_path / "r.csv", "--json",
    )  # fmt: skip
    summary = _json(res)
    assert summary["n_cameras"] == 3 and summary["sequencing"] == "partial"


def test_bad_recordings_get_one_line(shard, tmp_path):
    rec = tmp_path / "rec"
    _export(shard, rec)
    cal = rec / "calibration.toml"
    res = _reconstruct("--calibration", cal, "--keypoints", rec / "cam_0", rec / "cam_9", "--fps", "30")
    assert res.exit_code == 1 and "cam_9" in res.output and len(res.output.strip().splitlines()) == 1
    shutil.copytree(rec / "cam_1", tmp_path / "camX")
    res = _reconstruct("--calibration", cal, "--keypoints", rec / "cam_0", tmp_path / "camX", "--fps", "30")
    assert res.exit_code == 1 and "camera 'camX' is not in calibration" in res.output
    assert len(res.output.strip().splitlines()) == 1
    ts = rec / "cam_2_timestamps.csv"
    ts.write_text("frame,0.0\nframe,0.1\n")
    res = _reconstruct(rec / "project.toml", "--method", "pseudo")
    assert res.exit_code == 1 and "cam_2_timestamps.csv: has 2 frame times" in res.output
    assert len(res.output.strip().splitlines()) == 1
    (tmp_path / "r.trc").write_text("x")
    res = _reconstruct(rec / "project.toml", "--out", tmp_path / "r.trc")
    assert res.exit_code == 1 and "pass --overwrite" in res.output
    res = CliRunner().invoke(gttdata_main, ["export", str(shard), "--out", str(rec)])
    assert res.exit_code == 1 and "--overwrite" in res.output


def test_clock_recovery_on_a_recording_writes_recovered_times(shard, tmp_path):
    project = _export(shard, tmp_path / "rec")
    trc = tmp_path / "s.trc"
    got = _json(_reconstruct(project, "--method", "sync", "--no-weights", "--out", trc, "--json"))
    ref = _json(_reconstruct(shard, "--method", "sync", "--sequencing", "partial", "--json"))
    assert got["mpjpe_mm"] == pytest.approx(ref["mpjpe_mm"], rel=1e-6)
    _, t, _, _ = read_trc(trc)
    assert np.all(np.diff(t) >= 0) and t[-1] > 0.2  # recovered clock times (0.33 s of capture), not ranks


def test_unit_warnings_are_one_line_on_stderr(shard, tmp_path):
    project = _export(shard, tmp_path / "rec", "--units", "mm")
    cal = tmp_path / "rec" / "calibration.toml"
    cal.write_text(cal.read_text().replace('units = "mm"\n', ""))
    project.write_text(project.read_text().replace('calibration_units = "mm"\n', ""))
    res = _reconstruct(project, "--method", "pseudo")  # detected: one line says so
    assert res.exit_code == 0 and res.stderr.count("warning: ") == 1 and "read as mm" in res.stderr
    res = _reconstruct(project, "--method", "pseudo", "--calibration-units", "m")  # the mistake, named
    assert res.exit_code == 0 and res.stderr.count("warning: ") == 1
    assert "km from the origin" in res.stderr and "--calibration-units mm" in res.stderr
