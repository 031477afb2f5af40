"""Tests for Motion: validation, resampling, trimming, mirroring and bone scaling vs closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.mocap.motion import Motion
from gttdata.skeleton import Skeleton, cmu31

#: A 3-joint chain: root, a left and a right child.
_SK3 = Skeleton("toy3", ("root", "lhand", "rhand"), (-1, 0, 0))


def _linear_motion(T: int = 11, fps: float = 10.0) -> Motion:
    """Every joint moves at constant velocity v_j = (j + 1, 0, 0.5) m/s from a fixed offset."""
    t = np.arange(T) / fps
    offs = np.array([[0.0, 0.0, 1.0], [0.0, 0.3, 1.0], [0.0, -0.3, 1.0]])
    vel = np.array([[1.0, 0.0, 0.5], [2.0, 0.0, 0.5], [3.0, 0.0, 0.5]])
    pos = offs[None] + t[:, None, None] * vel[None]
    return Motion(positions=pos, fps_hz=fps, skeleton=_SK3, name="lin")


def test_smoke_properties():
    m = _linear_motion()
    assert m.n_frames == 11
    assert m.duration_s == pytest.approx(1.0)
    np.testing.assert_allclose(m.times_s, np.arange(11) / 10.0)
    assert m.positions.dtype == np.float64


@pytest.mark.parametrize(
    ("positions", "fps", "match"),
    [
        (np.zeros((5, 3)), 10.0, r"\(T, J, 3\)"),
        (np.zeros((0, 3, 3)), 10.0, "at least 1 frame"),
        (np.zeros((5, 4, 3)), 10.0, "4 joints"),
        (np.full((5, 3, 3), np.nan), 10.0, "NaN"),
        (np.zeros((5, 3, 3)), 0.0, "fps_hz"),
        (np.zeros((5, 3, 3)), float("inf"), "fps_hz"),
    ],
)
def test_invalid_motion_raises(positions, fps, match):
    with pytest.raises(ValueError, match=match):
        Motion(positions=positions, fps_hz=fps, skeleton=_SK3)


@pytest.mark.parametrize("new_fps", [30.0, 7.5, 25.0, 10.0])
def test_resample_linear_motion_is_exact(new_fps):
    m = _linear_motion()
    r = m.resample(new_fps)
    n = int(np.floor(1.0 * new_fps + 1e-9)) + 1
    assert r.n_frames == n
    assert r.fps_hz == new_fps
    np.testing.assert_allclose(r.positions, _positions_at(np.arange(n) / new_fps), atol=1e-12)


def _positions_at(t: np.ndarray) -> np.ndarray:
    m = _linear_motion()
    vel = (m.positions[1] - m.positions[0]) * m.fps_hz
    return m.positions[0][None] + t[:, None, None] * vel[None]


def test_sample_at_clamps_outside():
    m = _linear_motion()
    out = m.sample_at(np.array([-1.0, 0.05, 5.0]))
    np.testing.assert_allclose(out[0], m.positions[0])
    np.testing.assert_allclose(out[1], 0.5 * (m.positions[0] + m.positions[1]))
    np.testing.assert_allclose(out[2], m.positions[-1])


def test_resample_rejects_bad_fps():
    with pytest.raises(ValueError, match="fps_hz"):
        _linear_motion().resample(-3.0)


def test_trim_keeps_closed_interval():
    m = _linear_motion()
    tr = m.trim(0.2, 0.5)
    assert tr.n_frames == 4
    np.testing.assert_array_equal(tr.positions, m.positions[2:6])
    assert m.trim().n_frames == m.n_frames


def test_trim_empty_raises():
    with pytest.raises(ValueError, match="keeps no frame"):
        _linear_motion().trim(2.0, 3.0)


def test_mirror_reflects_axis_and_swaps_sides():
    m = _linear_motion()
    mm = m.mirror(axis=1)
    expect = m.positions[:, [0, 2, 1]].copy()
    expect[..., 1] *= -1
    np.testing.assert_array_equal(mm.positions, expect)
    np.testing.assert_allclose(mm.mirror(axis=1).positions, m.positions)
    assert mm.name == "lin+mirror"


def test_mirror_cmu31_is_involution():
    rng = np.random.default_rng(0)
    m = Motion(rng.normal(size=(4, 31, 3)), 120.0, cmu31())
    np.testing.assert_allclose(m.mirror().mirror().positions, m.positions)


def test_scale_bones_uniform_closed_form():
    m = _linear_motion()
    s = m.scale_bones(2.0)
    np.testing.assert_allclose(s.positions[:, 0], m.positions[:, 0])
    np.testing.assert_allclose(s.bone_lengths(), 2.0 * m.bone_lengths())
    d0 = m.positions[:, 1] - m.positions[:, 0]
    d1 = s.positions[:, 1] - s.positions[:, 0]
    np.testing.assert_allclose(d1, 2.0 * d0)


def test_scale_bones_chain_moves_descendants():
    """Chain a-b-c along x with unit bones; scaling bone b by 3 shifts c by 2 along x."""
    sk = Skeleton("chain", ("a", "b", "c"), (-1, 0, 1))
    pos = np.array([[[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]]])
    s = Motion(pos, 30.0, sk).scale_bones(np.array([1.0, 3.0, 1.0]))
    np.testing.assert_allclose(s.positions[0], [[0, 0, 0], [3, 0, 0], [4, 0, 0]])


def test_bone_lengths_shape():
    m = Motion(np.zeros((7, 31, 3)), 120.0, cmu31())
    assert m.bone_lengths().shape == (7, 30)
