"""MPJPE, PA-MPJPE and Kendall tau against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm, pa_mpjpe_mm


def test_mpjpe_hand_values():
    gt = np.zeros((2, 2, 3))
    pred = np.zeros((2, 2, 3))
    pred[0, 0] = [0.003, 0.004, 0.0]  # 5 mm
    pred[1, 1] = [0.0, 0.0, -0.011]  # 11 mm
    # mean over all 4 joints, the two exact ones included: (5 + 0 + 0 + 11) / 4
    assert mpjpe_mm(pred, gt) == pytest.approx(4.0)


def test_mpjpe_is_per_joint_not_per_coordinate():
    # The reference's transposed-matrix mistake averaged over the wrong axis; here a 3-4-5 offset is 5 mm.
    pred = np.array([[[0.003, 0.004, 0.0]]])
    assert mpjpe_mm(pred, np.zeros((1, 1, 3))) == pytest.approx(5.0)


@pytest.mark.parametrize(
    ("pred_shape", "gt_shape"),
    [((4, 2, 3), (3, 2, 4)), ((6, 4), (6, 4)), ((4, 2, 3), (4, 2, 2)), ((0, 2, 3), (0, 2, 3))],
)
def test_mpjpe_rejects_bad_shapes(pred_shape, gt_shape):
    with pytest.raises(ValueError, match="shape"):
        mpjpe_mm(np.zeros(pred_shape), np.zeros(gt_shape))


def test_mpjpe_rejects_transposed_layout():
    X = np.random.default_rng(0).normal(size=(5, 4, 3))
    with pytest.raises(ValueError):
        mpjpe_mm(X.transpose(2, 1, 0), X)


def test_pa_mpjpe_removes_similarity_but_not_shape():
    rng = np.random.default_rng(1)
    gt = rng.normal(size=(3, 6, 3))
    th = 0.7
    R = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    moved = 1.7 * gt @ R.T + np.array([0.3, -2.0, 5.0])
    assert pa_mpjpe_mm(moved, gt) == pytest.approx(0.0, abs=1e-9)
    assert mpjpe_mm(moved, gt) > 100.0
    # A reflection is not a rotation: a mirrored shape keeps an error.
    mirrored = gt * np.array([1.0, 1.0, -1.0])
    assert pa_mpjpe_mm(mirrored, gt) > 1.0


def test_pa_mpjpe_hand_value():
    # Two joints at +-1 on x; prediction stretched by 2 and shifted: similarity removes both exactly.
    gt = np.array([[[-1.0, 0, 0], [1.0, 0, 0]]])
    pred = np.array([[[-2.0, 5, 0], [2.0, 5, 0]]])
    assert pa_mpjpe_mm(pred, gt) == pytest.approx(0.0, abs=1e-9)


def test_kendall_tau_hand_values():
    assert kendall_tau(np.arange(5), np.arange(5)) == pytest.approx(1.0)
    assert kendall_tau(np.arange(5)[::-1], np.arange(5)) == pytest.approx(1.0)  # reversal is unobservable
    # one adjacent swap among 4: concordant 5, discordant 1 of 6 pairs -> tau = 4/6
    assert kendall_tau(np.array([1, 0, 2, 3]), np.arange(4)) == pytest.approx(4 / 6)
    # reversed with one swap: |tau| is the same
    assert kendall_tau(np.array([2, 3, 1, 0]), np.arange(4)) == pytest.approx(4 / 6)
    assert kendall_tau(np.array([0]), np.array([0])) == 1.0


def test_kendall_tau_shape_error():
    with pytest.raises(ValueError, match="shape"):
        kendall_tau(np.arange(4), np.arange(5))
