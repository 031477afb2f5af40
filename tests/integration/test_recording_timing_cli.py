"""``gttnet reconstruct`` of a recording without, or with a wrong, ``--fps``; a camera with no usable detection."""

from __future__ import annotations

import json
import re

import pytest
from click.testing import CliRunner

from gttdata.cli import main as gttdata_main
from gttnet.cli import main as gttnet_main

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """An exported recording of three cameras at 25 / 50 / 60 Hz (camera folders cam_0..cam_2)."""
    from gttdata.shards.writer import ShardWriter
    from tests.gttnet.test_sync import _capture

    sample = _capture(offsets_s=(0.0, 0.2, 0.1), fps=(25.0, 50.0, 60.0), end_s=2.0, seed=4)
    d = tmp_path_factory.mktemp("timing")
    with ShardWriter(d / "shards", split="test") as w:
        w.write(sample)
    shard = sorted((d / "shards").glob("*.h5"))[0]
    res = CliRunner().invoke(
        gttdata_main, ["export", str(shard), "--out", str(d / "rec"), "--format", "openpose"]
    )
    assert res.exit_code == 0, res.output
    return d / "rec"


def _run(rec, *args, calibration=None):
    cal = calibration or rec / "calibration.toml"
    keypoints = [str(rec / f"cam_{i}") for i in range(3)]
    argv = ["reconstruct", "--calibration", str(cal), "--keypoints", *keypoints, "--method", "sync", "--json"]
    res = CliRunner().invoke(gttnet_main, [*argv, *args])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout.strip().splitlines()[-1]), res.stderr


def test_no_fps_means_estimated_rates_and_a_warning(recording):
    summary, err = _run(recording)
    line = next(x for x in err.splitlines() if "no frame rate given" in x)
    assert line.startswith("warning: ") and "cam_0 25, cam_1 50, cam_2 60 Hz" in line, err
    assert summary["frame_rates_hz"] == {"cam_0": 25.0, "cam_1": 50.0, "cam_2": 60.0}
    assert "cameras_left_out" not in summary


def test_a_wrong_fps_is_named_with_the_likely_rate(recording):
    summary, err = _run(recording, "--fps", "25", "--fps", "30", "--fps", "60")
    assert re.search(
        r"^warning: camera cam_1: the given 30 Hz does not explain the images .*likely 50 Hz", err, re.M
    ), err
    assert summary["frame_rates_hz"]["cam_1"] == 50.0
    _, right = _run(recording, "--fps", "25", "--fps", "50", "--fps", "60")
    assert "warning" not in right


def test_a_camera_with_nan_distortion_is_left_out_with_a_warning(recording, tmp_path):
    text = (recording / "calibration.toml").read_text()
    head, sep, tail = text.partition("[cam_1]")
    tail = re.sub(r"distortions = \[[^\]]*\]", "distortions = [nan, 0.0, 0.0, 0.0, 0.0]", tail, count=1)
    cal = tmp_path / "calibration.toml"
    cal.write_text(head + sep + tail)
    summary, err = _run(recording, "--fps", "25", "--fps", "50", "--fps", "60", calibration=cal)
    assert "warning: camera 'cam_1': no usable detection (its distortion coefficients" in err, err
    assert "warning: camera cam_1 left out of the timed solve" in err
    assert list(summary["cameras_left_out"]) == ["cam_1"] and "cam_1" not in summary["frame_rates_hz"]
