"""auto charges clocks recovered on estimated streams for the clock-fit residual right clocks would not leave."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gttnet.auto import CLOCK_EXCESS_FACTOR, _clock_excess
from gttnet.methods import Reconstruction
from gttnet.sync.streams import expected_clock_rms_px


def _rec(rms: float, *, estimated: bool = True) -> Reconstruction:
    quality = {"expected_error_mm": 4.0, "sigma_px": 2.0, "noise_mm": 6.0, "reasons": ["ok"]}
    info = {"streams_estimated": estimated, "clock_rms_px": rms, "quality": quality}
    return Reconstruction(
        points3d=np.zeros((3, 2, 3)), method="stream-sync", info=info, uncertainty_mm=np.ones((3, 2))
    )


def test_excess_over_right_clocks_is_added_in_quadrature():
    rms = 4.0
    rows = [{"expected_error_mm": 4.0, "reasons": ["ok"]}]
    out = _clock_excess([_rec(rms)], rows)[0]
    excess_px = math.sqrt(rms**2 - expected_clock_rms_px(2.0) ** 2)
    want = math.hypot(4.0, CLOCK_EXCESS_FACTOR * excess_px * 6.0 / 2.0)
    q = out.info["quality"]
    assert q["expected_error_mm"] == pytest.approx(want, abs=1e-3)
    assert rows[0]["expected_error_mm"] == q["expected_error_mm"]
    assert any("clock fit leaves" in r for r in q["reasons"])
    assert out.uncertainty_mm is not None and out.uncertainty_mm[0, 0] == pytest.approx(want / 4.0, abs=1e-3)
    # applied once: a second pass (auto calls it after every candidate) changes nothing
    again = _clock_excess([out], rows)[0]
    assert again.info["quality"]["expected_error_mm"] == q["expected_error_mm"]


def test_right_clocks_and_given_streams_are_not_charged():
    right = _clock_excess([_rec(0.9 * expected_clock_rms_px(2.0))], [{}])[0]
    assert right.info["quality"]["expected_error_mm"] == pytest.approx(4.0)
    given = _clock_excess([_rec(9.0, estimated=False)], [{}])[0]
    assert given.info["quality"]["expected_error_mm"] == 4.0
