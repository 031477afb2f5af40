"""Training losses against hand-computed values."""

from __future__ import annotations

import pytest
import torch

from gttnet import losses
from gttnet.model.affinity import AffinityOutput


def test_autoencoding_loss_mse_and_fro():
    a = torch.zeros(2, 3, 3)
    b = torch.zeros(2, 3, 3)
    b[0, 0] = torch.tensor([1.0, 2.0, 2.0])  # squared distance 9 over N·P = 6 images·points
    c = torch.zeros(2, 1, 3)
    d = torch.ones(2, 1, 3)  # squared 3 per point, N·P = 2
    assert losses.autoencoding_loss([(a, b), (c, d)]).item() == pytest.approx(9 / 6 + 6 / 2)
    assert losses.autoencoding_loss([(a, b)], norm="fro").item() == pytest.approx(3 / 6)
    assert losses.autoencoding_loss([(a, a)]).item() == 0.0
    with pytest.raises(ValueError, match="norm"):
        losses.autoencoding_loss([(a, b)], norm="l1")


def _aff(values, mask, keep):
    values = torch.tensor(values)
    keep = torch.tensor(keep)
    return AffinityOutput(values=values, mask=torch.tensor(mask), keep=keep, kept=values.gather(1, keep))


def test_affinity_loss_hand_computed():
    aff = _aff(
        [[0.9, 0.2, 0.0], [0.5, 0.5, 0.1]], [[True, True, False], [True, True, True]], [[0, 1], [0, 1]]
    )
    target = torch.tensor([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]])  # the padded slot's target is ignored
    whole = (0.1**2 + 0.2**2) + (0.5**2 + 0.5**2 + 0.1**2)
    kept = (0.1**2 + 0.2**2) + (0.5**2 + 0.5**2)
    assert losses.affinity_loss(aff, target).item() == pytest.approx((whole + kept) / 2)
    with pytest.raises(ValueError, match="shape"):
        losses.affinity_loss(aff, torch.zeros(2, 2))


def test_pseudo_targets_mark_first_real_slots():
    mask = torch.tensor([[True, True, True], [False, True, True], [True, False, False]])
    t = losses.pseudo_affinity_targets(mask, q=2)
    assert t.tolist() == [[1, 1, 0], [0, 1, 1], [1, 0, 0]]


def test_structure_loss_per_joint():
    x = torch.zeros(4, 2, 3)
    g = torch.zeros(4, 2, 3)
    g[..., 0] = 0.01  # 1 cm everywhere
    assert losses.structure_loss(x, g).item() == pytest.approx(1e-4)
    assert losses.structure_loss(x, g, norm="fro").item() == pytest.approx(0.01 * 8**0.5 / 8)
    with pytest.raises(ValueError, match="shape"):
        losses.structure_loss(x, g[:3])


def test_smoothness_zero_on_linear_motion_and_scale_free():
    n = 6
    t = torch.arange(n, dtype=torch.float64)
    x = torch.stack([t, 2 * t, -t], -1)[:, None, :].repeat(1, 2, 1)  # linear trajectory, J = 2
    A = torch.zeros(n, n, dtype=torch.float64)
    for i in range(1, n - 1):
        A[i, i - 1] = A[i, i + 1] = 0.5
    A[0, 1] = A[n - 1, n - 2] = 1.0
    smooth_only = losses.smoothness_loss(A, x, lambda1=0.0)
    # Interior rows are exact midpoints; the two end rows copy their neighbour (residual = one step).
    assert smooth_only.item() == pytest.approx(2 * 2 * (1 + 4 + 1) / (n * 2))
    both = losses.smoothness_loss(A, x, lambda1=0.1)
    assert both > smooth_only
    torch.testing.assert_close(losses.smoothness_loss(5.0 * A, x), both)


def test_smoothness_needs_no_ground_truth_and_is_differentiable():
    A = torch.rand(5, 5, dtype=torch.float64, requires_grad=True)
    x = torch.randn(5, 3, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda a, y: losses.smoothness_loss(a, y), (A, x))


def test_pointnet_loss():
    r = torch.ones(3, 4, 3)
    assert losses.pointnet_loss(r, torch.zeros(3, 4, 3)).item() == pytest.approx(3.0)
    with pytest.raises(ValueError, match="shape"):
        losses.pointnet_loss(r, torch.zeros(3, 5, 3))
