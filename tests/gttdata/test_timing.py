"""Per-camera clocks: no two images are ever concurrent, streams keep their order, counts match rates."""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.capture.timing import (
    camera_offsets,
    min_cross_camera_gap,
    sample_timestamps,
    separate_timestamps,
)

MIN_GAP = 1e-4


def _capture(fps, *, stagger="even", jitter_s=0.0, drift_ppm=0.0, seed=0, duration_s=3.0):
    rng = np.random.default_rng(seed)
    fps = np.asarray(fps, dtype=np.float64)
    offsets = camera_offsets(fps, stagger=stagger, rng=rng)
    return sample_timestamps(
        fps, duration_s, offsets_s=offsets, rng=rng, jitter_s=jitter_s, drift_ppm=drift_ppm, min_gap_s=MIN_GAP
    )


def test_even_stagger_equal_rates_is_a_perfect_interleave():
    cam, t, si = _capture([30.0] * 4, duration_s=2.5)
    assert t.shape == (300,)
    assert np.all(np.diff(t) > 0)
    np.testing.assert_allclose(np.diff(t), 1.0 / 120.0, atol=1e-12)
    assert min_cross_camera_gap(t, cam) == pytest.approx(1.0 / 120.0)
    for v in range(4):
        assert np.array_equal(si[cam == v], np.arange(75))


@pytest.mark.parametrize("seed", range(25))
@pytest.mark.parametrize("stagger", ["even", "random"])
def test_mixed_rates_with_jitter_and_drift_never_concurrent(seed: int, stagger: str):
    rng = np.random.default_rng(1000 + seed)
    v = int(rng.integers(2, 7))
    fps = rng.choice([7.5, 15.0, 30.0], size=v)
    jitter = float(rng.choice([0.0, 1e-3, 5e-3]))
    drift = rng.normal(0.0, 50.0, size=v)
    cam, t, si = _capture(fps, stagger=stagger, jitter_s=jitter, drift_ppm=drift, seed=seed)
    assert min_cross_camera_gap(t, cam) >= MIN_GAP * (1 - 1e-9)
    assert np.all(np.diff(t) > 0)
    for c in range(v):
        mine = cam == c
        assert np.all(np.diff(t[mine]) > 0)
        assert np.array_equal(si[mine], np.arange(mine.sum()))
        assert abs(mine.sum() - 3.0 * fps[c]) <= 1


def test_harmonic_rates_are_separated_by_construction():
    # 7.5/15/30 Hz with the even stagger need no nudging: the gap is the stagger slot itself.
    cam, t, _ = _capture([7.5, 15.0, 30.0])
    assert min_cross_camera_gap(t, cam) == pytest.approx(1.0 / (3 * 30.0))


@pytest.mark.parametrize(
    "fps", [[25.0, 30.0], [29.97, 30.0, 24.0], [30.0, 30.0, 30.0, 30.0, 30.0, 30.0, 30.0]]
)
def test_non_harmonic_rates_get_separated(fps):
    cam, t, _ = _capture(fps, duration_s=10.0)
    assert min_cross_camera_gap(t, cam) >= MIN_GAP * (1 - 1e-9)


def test_separate_timestamps_fixes_concurrent_images_without_reordering():
    t = np.array([0.0, 0.0, 0.0, 0.5, 0.50000001, 1.0])
    out = separate_timestamps(t, min_gap_s=1e-3)
    assert np.all(np.diff(np.sort(out)) >= 1e-3 - 1e-12)
    assert np.array_equal(np.argsort(out, kind="stable"), np.argsort(t, kind="stable"))
    assert np.max(np.abs(out - t)) < t.size * 1e-3
    assert out[-1] == 1.0


def test_offsets_lie_within_one_period():
    rng = np.random.default_rng(3)
    fps = np.array([7.5, 15.0, 30.0, 30.0])
    for stagger in ("even", "random"):
        off = camera_offsets(fps, stagger=stagger, rng=rng)
        assert np.all(off >= 0) and np.all(off < 1.0 / fps)
    with pytest.raises(ValueError, match="stagger must be one of"):
        camera_offsets(fps, stagger="none", rng=rng)


def test_min_gap_single_camera_is_inf():
    assert min_cross_camera_gap(np.arange(5.0), np.zeros(5, dtype=int)) == np.inf
