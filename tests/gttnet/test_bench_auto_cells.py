"""The input faults of benchmarks/bench_auto.py's cells: what each cell hands the methods."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def bench():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import bench_auto
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return bench_auto


def _sample(cell: str):
    return build_sample(load_recipe(str(ROOT / "recipes/gttdata/ood" / f"{cell}.yaml"), []), "val", 0)[0]


def test_wrong_rate_declares_one_camera_wrong_and_the_others_right(bench):
    sample = _sample("wrong_rate")
    obs, _, opts = bench._cell_view(sample, "partial", "wrong_rate")
    assert opts["fps"] == {0: 50.0, 1: 30.0, 2: 50.0, 3: 50.0}
    plain, _ = make_view(sample, "partial")
    ratio = obs.stream_time_s / np.where(plain.stream_time_s == 0, np.nan, plain.stream_time_s)
    np.testing.assert_allclose(np.nanmax(ratio[obs.cam_id == 1]), 50.0 / 30.0)
    np.testing.assert_allclose(ratio[(obs.cam_id != 1) & np.isfinite(ratio)], 1.0)
    np.testing.assert_array_equal(opts["frame_times_s"], obs.stream_time_s)


def test_second_person_replaces_the_subject_in_some_frames_of_two_cameras(bench):
    sample = _sample("second_person")
    obs, gt, _ = bench._cell_view(sample, "full", "second_person")
    plain, _ = make_view(sample, "full")
    moved = np.nanmax(np.linalg.norm(obs.keypoints_px - plain.keypoints_px, axis=-1), axis=1) > 50.0
    assert set(np.unique(obs.cam_id[moved])) == {2, 3}
    for c in (2, 3):
        share = moved[obs.cam_id == c].mean()
        assert 0.15 <= share <= 0.21, share  # a fifth of the camera's frames (some detections stay near)
    assert not moved[np.isin(obs.cam_id, (0, 1))].any()
