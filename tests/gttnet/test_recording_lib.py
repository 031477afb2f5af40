"""gttnet.recording: --fps forms, TRC frame, uniform clock and filters."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from gttdata.errors import KeypointFormatError
from gttdata.recording import CameraInput, RecordingSpec
from gttnet.io.motion_files import MotionTable
from gttnet.recording import apply_fps, filter_motion, parse_filter, parse_fps, to_trc_frame


def _spec(n=3):
    cams = tuple(CameraInput(name=f"cam_{i}", keypoints=Path(f"k{i}")) for i in range(n))
    return RecordingSpec(calibration=Path("c.toml"), cameras=cams)


@pytest.mark.parametrize(
    "fps, want",
    [("30", [30, 30, 30]), ("25,30,60", [25, 30, 60]), (("25", "30", "60"), [25, 30, 60]),
     ("cam_1=60", [None, 60, None]), ("0=25,2=50", [25, None, 50])],
)  # fmt: skip
def test_fps_forms(fps, want):
    assert [c.fps for c in apply_fps(_spec(), parse_fps(fps)).cameras] == want


@pytest.mark.parametrize("bad", ["fast", "30,x", "0", "-5", "cam_1=abc", "nan"])
def test_bad_fps_is_one_error(bad):
    with pytest.raises(KeypointFormatError, match="--fps"):
        parse_fps(bad)


def test_fps_count_and_names_checked():
    with pytest.raises(KeypointFormatError, match=r"one per camera \(3: cam_0, cam_1, cam_2\), got 2"):
        apply_fps(_spec(), parse_fps("25,30"))
    with pytest.raises(KeypointFormatError, match="no camera 'cam_7'"):
        apply_fps(_spec(), parse_fps("cam_7=30"))


@given(st.lists(st.floats(0.5, 500.0), min_size=1, max_size=6))
def test_parse_fps_round_trip(rates):
    got = parse_fps(",".join(repr(r) for r in rates))
    assert (got if isinstance(got, list) else [got]) == rates


def test_trc_frame_is_a_rotation():
    R = to_trc_frame(np.eye(3), "y")  # rows: images of the world axes
    assert np.isclose(np.linalg.det(R), 1.0) and R[2].tolist() == [0.0, 1.0, 0.0]  # world z is TRC Y
    assert to_trc_frame(np.eye(3), "z").tolist() == np.eye(3).tolist()


def _table(x, rate=100.0):
    m = x.shape[0]
    return MotionTable(
        points3d=x, time_s=np.arange(m) / rate, camera=("",) * m, frame=np.full(m, -1), row=np.full(m, -1),
        joint_names=("a",), timed=True, rate_hz=rate,
    )  # fmt: skip


def test_butterworth_keeps_slow_motion_and_removes_fast_noise():
    t = np.arange(400) / 100.0
    slow = np.sin(2 * np.pi * 1.0 * t)
    fast = 0.2 * np.sin(2 * np.pi * 30.0 * t)
    x = np.zeros((400, 1, 3))
    x[:, 0, 0] = slow + fast
    x[150:160] = np.nan  # a gap: each side is filtered on its own and the gap stays
    out = filter_motion(_table(x), *parse_filter("butterworth:6")).points3d[:, 0, 0]
    ok = np.isfinite(out)
    assert np.isnan(out[150:160]).all() and ok.sum() == 390
    inner = np.zeros(400, bool)
    inner[20:130] = inner[180:380] = True  # away from the ends of each stretch (filtfilt's edge transients)
    assert np.max(np.abs(out - slow)[inner]) < 0.02  # the 30 Hz part is gone, the 1 Hz part kept


@pytest.mark.parametrize("spec", ["gaussian:2", "median:5"])
def test_gaussian_and_median_reduce_noise(spec):
    rng = np.random.default_rng(0)
    x = np.zeros((300, 1, 3)) + rng.normal(0, 0.01, (300, 1, 3))
    out = filter_motion(_table(x), *parse_filter(spec)).points3d
    assert np.std(out) < 0.6 * np.std(x)


def test_filter_errors():
    with pytest.raises(KeypointFormatError, match="--filter"):
        parse_filter("lowpass:6")
    with pytest.raises(ValueError, match="below half the rate"):
        filter_motion(_table(np.zeros((50, 1, 3))), "butterworth", 60.0)
    uneven = dataclasses.replace(_table(np.zeros((5, 1, 3))), time_s=np.array([0, 0.1, 0.15, 0.3, 0.4]))
    with pytest.raises(ValueError, match="uniform clock"):
        filter_motion(uneven, "gaussian", 1.0)
