"""TRC / C3D / CSV writers and readers: round trips with missing joints, resampling, time order."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gttnet.io.motion_files import (
    MotionTable,
    read_c3d_points,
    read_motion_csv,
    read_trc,
    resample,
    write_motion,
)


@st.composite
def tables(draw):
    m = draw(st.integers(1, 12))
    j = draw(st.integers(1, 5))
    X = np.reshape(
        draw(st.lists(st.floats(-5, 5, width=64), min_size=m * j * 3, max_size=m * j * 3)), (m, j, 3)
    )
    gone = np.reshape(draw(st.lists(st.booleans(), min_size=m * j, max_size=m * j)), (m, j))
    X[gone] = np.nan
    t = np.cumsum(draw(st.lists(st.floats(1e-3, 0.1), min_size=m, max_size=m)))
    cams = tuple(draw(st.lists(st.sampled_from(["cam_0", "cam_1", "left"]), min_size=m, max_size=m)))
    return MotionTable(
        points3d=X, time_s=t, camera=cams, frame=np.arange(m), row=np.arange(m),
        joint_names=tuple(f"joint{i}" for i in range(j)), timed=True, rate_hz=30.0,
    )  # fmt: skip


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(table=tables())
def test_round_trips(tmp_path_factory, table):
    d = tmp_path_factory.mktemp("motion")
    names, t, P, units = read_trc(write_motion(table, d / "r.trc"))
    assert units == "m" and names == table.joint_names
    np.testing.assert_array_equal(np.isnan(P), np.isnan(table.points3d))
    np.testing.assert_allclose(P, table.points3d, atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(t, table.time_s, atol=1e-9)
    labels, tc, C, cu = read_c3d_points(write_motion(table, d / "r.c3d"))
    assert cu == "m" and labels == table.joint_names
    np.testing.assert_array_equal(np.isnan(C).any(-1), np.isnan(table.points3d).any(-1))
    np.testing.assert_allclose(C, table.points3d, atol=1e-6, equal_nan=True)  # float32
    np.testing.assert_allclose(tc, table.time_s, rtol=1e-6, atol=1e-6)
    n2, t2, cams, frames, Q = read_motion_csv(write_motion(table, d / "r.csv"))
    assert n2 == table.joint_names and tuple(cams) == table.camera
    np.testing.assert_allclose(Q, table.points3d, atol=1e-9, equal_nan=True)


def test_resample_is_linear_and_refuses_untimed():
    t = np.array([0.0, 0.1, 0.25, 0.4])
    X = np.stack([np.stack([t, 2 * t, np.ones(4)], -1)], 1)  # one joint moving linearly
    X[2, 0] = np.nan  # a gap is bridged linearly
    table = MotionTable(X, t, ("a",) * 4, np.arange(4), np.arange(4), ("j",), True, 10.0)
    r = resample(table, 20.0)
    np.testing.assert_allclose(r.time_s, np.arange(9) / 20.0)
    np.testing.assert_allclose(r.points3d[:, 0, 0], r.time_s, atol=1e-12)
    np.testing.assert_allclose(r.points3d[:, 0, 1], 2 * r.time_s, atol=1e-12)
    with pytest.raises(ValueError, match="needs times"):
        resample(MotionTable(X, t, ("a",) * 4, np.arange(4), np.arange(4), ("j",), False, 10.0), 20.0)


def test_write_motion_rejects_unknown_suffix(tmp_path):
    table = MotionTable(np.zeros((1, 1, 3)), np.zeros(1), ("a",), np.zeros(1), np.zeros(1), ("j",), True, 1.0)
    with pytest.raises(ValueError, match="suffix must be one of .trc, .c3d, .csv"):
        write_motion(table, tmp_path / "r.bvh")
