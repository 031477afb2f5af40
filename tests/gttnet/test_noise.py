"""The capture's own 2-D noise from its camera streams, and the per-image ray weights it gives the DLOE layer."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gttdata.capture.views import make_view
from gttnet.geometry.noise import MIN_SAMPLES, auto_lambda2, stream_noise_px
from gttnet.solvers.xstep import noise_aware_lambda2, solve_structure


@pytest.mark.parametrize("sigma", [0.5, 2.0, 5.0])
def test_stream_noise_recovers_the_noise_of_smooth_tracks(sigma):
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 2.0, 300)
    clean = 200.0 * np.stack([np.sin(t + p) for p in range(6)], -1)[..., None] + np.zeros((300, 6, 2))
    cam = np.repeat([0, 1], 150)
    si = np.tile(np.arange(150), 2)
    est = stream_noise_px(clean + rng.normal(0, sigma, clean.shape), np.ones((300, 6), bool), cam, si)
    assert est == pytest.approx(sigma, rel=0.1)


def test_stream_noise_keeps_the_least_biased_camera_and_skips_gaps():
    rng = np.random.default_rng(2)
    n = 200
    px = rng.normal(0, 1.0, (2 * n, 4, 2))
    px[n:] += rng.normal(0, 5.0, (n, 4, 2))  # a second camera with more spread (e.g. fast motion)
    cam = np.repeat([0, 1], n)
    si = np.tile(np.arange(n), 2)
    assert stream_noise_px(px, np.ones((2 * n, 4), bool), cam, si) == pytest.approx(1.0, rel=0.15)
    # every other frame dropped: no three consecutive frames, nothing to measure
    assert stream_noise_px(px, np.ones((2 * n, 4), bool), cam, 2 * si) is None
    few = MIN_SAMPLES // 8  # fewer values than MIN_SAMPLES in any camera (4 joints x 2 axes per triple)
    assert stream_noise_px(px[:few], np.ones((few, 4), bool), cam[:few], si[:few]) is None


def test_auto_lambda2_weights_each_image_by_its_own_depth(scene_factory):
    sample = scene_factory(n_cameras=4, n_joints=6, frames_per_camera=30, sigma_px=2.0, seed=4)
    obs, gt = make_view(sample, "full")
    lam, sigma = auto_lambda2(
        obs.keypoints_px, obs.visible, obs.cam_id, obs.stream_index, obs.K, obs.cam_from_world, gt.points3d
    )
    assert sigma == pytest.approx(2.0, rel=0.35) and lam.shape == (obs.n_images,)
    T = obs.cam_from_world
    depth = np.einsum("nk,njk->nj", T[:, 2, :3], gt.points3d) + T[:, None, 2, 3]
    i = 0
    d_i = float(np.median(depth[i][obs.visible[i]]))
    assert lam[i] == pytest.approx(noise_aware_lambda2(sigma, float(obs.K[i, 0, 0]), d_i))
    # farther images get smaller weights: lambda2 ~ 1 / depth^2
    med = np.array([np.median(depth[n][obs.visible[n]]) for n in range(obs.n_images)])
    assert np.allclose(lam * med**2, lam[0] * med[0] ** 2)


def test_a_constant_per_image_weight_is_the_scalar_weight(scene_factory):
    sample = scene_factory(n_cameras=3, n_joints=4, frames_per_camera=10, sigma_px=1.0, seed=5)
    obs, gt = make_view(sample, "full")
    A = torch.tensor(gt.affinity_binary())
    args = (A, obs.centers(), obs.rays(), obs.visible)
    for method in ("dense", "sparse"):
        a = solve_structure(*args, lambda2=0.3, method=method)
        b = solve_structure(*args, lambda2=np.full(obs.n_images, 0.3), method=method)
        torch.testing.assert_close(a, b)
    with pytest.raises(ValueError, match="lambda2 > 0"):
        solve_structure(*args, lambda2=np.r_[0.0, np.ones(obs.n_images - 1)])
    with pytest.raises(ValueError, match=r"lambda2 must be a number or have shape \(30,\)"):
        solve_structure(*args, lambda2=np.ones(7))


def test_gttnet_auto_ray_weight_reports_the_noise_it_measured(scene_factory):
    from gttnet.methods import reconstruct

    sample = scene_factory(n_cameras=4, n_joints=31, frames_per_camera=60, sigma_px=3.0, seed=6)
    obs, gt = make_view(sample, "full")
    rec = reconstruct(obs, "gttnet", lambda2="auto")
    assert rec.info["noise_px"] == pytest.approx(3.0, rel=0.35)
    assert rec.info["lambda2"] > 0  # the median of the per-image weights
    pinned = reconstruct(obs, "gttnet")
    assert pinned.info["noise_px"] is None and pinned.info["lambda2"] is None
    err = [np.linalg.norm(r.points3d - gt.points3d, axis=-1).mean() for r in (pinned, rec)]
    assert err[1] < err[0]  # 3 px of noise and the true temporal chain: leaving the rays pays
