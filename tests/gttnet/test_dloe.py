"""DLOE baseline: the simplex QP, the W- and D-steps, and accuracy against pseudo-triangulation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from gttdata.capture.views import make_view
from gttnet.baselines._simplex import project_simplex, solve_simplex_qp
from gttnet.baselines.dloe import DLOEParams, candidate_neighbours, d_step, mds_embedding, w_step
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
from gttnet.geometry.triangulation import pseudo_triangulate
from gttnet.methods import reconstruct


@pytest.fixture(scope="module")
def noisy_scene():
    """Paper-like rig at toy size: 4 cameras, 12 joints, 25 frames each (N = 100), sigma 2 px."""
    from tests.fixtures.scenes import make_scene

    return make_scene(n_cameras=4, n_joints=12, frames_per_camera=25, sigma_px=2.0, seed=11)


def test_project_simplex_properties():
    rng = np.random.default_rng(0)
    v = rng.normal(size=(50, 6)) * 3
    mask = rng.random((50, 6)) > 0.3
    mask[0] = False
    p = project_simplex(v, mask)
    assert np.all(p >= 0) and np.all(p[~mask] == 0)
    np.testing.assert_allclose(p[mask.any(1)].sum(1), 1.0, atol=1e-12)
    assert np.all(p[0] == 0)
    # A point already on the simplex is its own projection.
    q = project_simplex(p[1:2], mask[1:2])
    np.testing.assert_allclose(q, p[1:2], atol=1e-12)


def test_simplex_qp_matches_slsqp():
    rng = np.random.default_rng(1)
    B, K = 12, 7
    G = rng.normal(size=(B, K, 20))
    H = np.einsum("bka,bla->bkl", G, G)
    g = rng.normal(size=(B, K)) * 4
    mask = np.ones((B, K), bool)
    mask[:, -1] = rng.random(B) > 0.5
    x = solve_simplex_qp(H, g, mask, n_iter=3000)
    for b in range(B):
        m = mask[b]
        Hb, gb = H[b][np.ix_(m, m)], g[b][m]
        ref = minimize(
            lambda z, Hb=Hb, gb=gb: z @ Hb @ z + gb @ z,
            np.full(m.sum(), 1.0 / m.sum()),
            bounds=[(0, 1)] * int(m.sum()),
            constraints=[{"type": "eq", "fun": lambda z: z.sum() - 1}],
            method="SLSQP",
            options={"ftol": 1e-14, "maxiter": 500},
        )
        f = x[b][m] @ Hb @ x[b][m] + gb @ x[b][m]
        assert f <= ref.fun + 1e-8


def test_d_step_constraints_and_monotonicity():
    rng = np.random.default_rng(2)
    n = 30
    X = rng.normal(size=(n, 4, 3))
    W = rng.random((n, n))
    np.fill_diagonal(W, 0)
    W /= W.sum(1, keepdims=True)
    d = d_step(X, W, np.zeros((n, n)), DLOEParams(lambda1=0.0))
    assert d.sum() == pytest.approx(n, rel=1e-9)
    assert np.all(d >= 0) and np.all(d <= n)
    # With lambda1 = lambda3 = 0 the optimum weights well-interpolated rows more: d falls with the residual.
    Y = X.reshape(n, -1)
    h = ((Y - W @ Y) ** 2).sum(1)
    pos = d > 0
    assert np.all(np.diff(d[pos][np.argsort(h[pos])]) <= 1e-9)


def test_w_step_recovers_interpolation_weights():
    """x_n halfway between two candidates on a line: the fit puts 0.5 / 0.5 on them.

    The exact fits form a line (a far candidate can stand in for a near one); the lambda1 compactness
    term picks the one with the nearest candidates.
    """
    X = np.zeros((4, 1, 3))
    X[:, 0, 0] = [0.0, 1.0, 2.0, 7.0]
    cand = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    params = DLOEParams(lambda1=0.01, lambda3=0.0, qp_iters=5000)
    w = w_step(X, cand, np.zeros((4, 4)), mds_embedding(X), np.zeros((4, 4)), np.ones(4), params)
    np.testing.assert_allclose(w[1], [0.5, 0.5, 0.0], atol=1e-6)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-12)


@pytest.mark.parametrize("seq", ["none", "partial", "full"])
def test_candidates_are_other_camera_images(noisy_scene, seq):
    obs, _ = make_view(noisy_scene, seq)
    pt = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id)
    cand = candidate_neighbours(obs, pt.cost, pt.order, 6)
    assert cand.shape == (obs.n_images, 6)
    rows, cols = np.nonzero(cand >= 0)
    assert np.all(obs.cam_id[cand[rows, cols]] != obs.cam_id[rows])
    if seq == "full":
        t = obs.timestamp_s
        first = cand[:, 0]
        other = obs.cam_id[:, None] != obs.cam_id[None, :]
        gap = np.where(other, np.abs(t[:, None] - t[None, :]), np.inf).min(1)
        np.testing.assert_allclose(np.abs(t[first] - t), gap)


@pytest.mark.parametrize("seq", ["none", "partial"])
def test_dloe_beats_pseudo_triangulation(noisy_scene, seq):
    obs, gt = make_view(noisy_scene, seq)
    pseudo = reconstruct(obs, "pseudo")
    dloe = reconstruct(obs, "dloe")
    e_pseudo = mpjpe_mm(pseudo.points3d, gt.points3d)
    e_dloe = mpjpe_mm(dloe.points3d, gt.points3d)
    assert e_dloe < 0.92 * e_pseudo, (e_dloe, e_pseudo)
    assert kendall_tau(dloe.order, gt.global_order) > 0.9
    assert 1 <= dloe.info["iterations"] <= 50


def test_dloe_options(noisy_scene):
    obs, _ = make_view(noisy_scene, "partial")
    rec = reconstruct(obs, "dloe", max_iter=1)
    assert rec.info["iterations"] == 1
    with pytest.raises(ValueError, match="has no option 'lambda9'"):
        reconstruct(obs, "dloe", lambda9=1.0)


def test_dloe_started_at_its_own_solution_stays_there(noisy_scene):
    obs, gt = make_view(noisy_scene, "none")
    first = reconstruct(obs, "dloe")
    # One round from the solution stays near it; one round from X_init (the cold start) does not.
    warm = reconstruct(obs, "dloe", x_start=first.points3d, max_iter=1)
    cold = reconstruct(obs, "dloe", max_iter=1)
    moved = mpjpe_mm(warm.points3d, first.points3d)
    assert moved < 0.5 * mpjpe_mm(cold.points3d, first.points3d)
    # Run to convergence it moves by a small fraction of the structure's error (the stopping tolerance
    # and the W-step's warm start, which a restart lacks, keep it from being exact).
    again = reconstruct(obs, "dloe", x_start=first.points3d)
    assert mpjpe_mm(again.points3d, first.points3d) < 0.2 * mpjpe_mm(first.points3d, gt.points3d)


def test_dloe_x_start_shape_is_checked(noisy_scene):
    obs, _ = make_view(noisy_scene, "none")
    with pytest.raises(ValueError, match=r"x_start must have shape \(\d+, \d+, 3\)"):
        reconstruct(obs, "dloe", x_start=np.zeros((2, 3)))
