"""Tests of the k-d tree candidate search: epipolar descriptors, exact candidate costs, recall vs dense."""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttnet.geometry.candidates import (
    candidate_partners,
    candidate_pseudo_triangulate,
    epipolar_descriptors,
    pair_costs,
)
from gttnet.geometry.neighbours import neighbourhoods
from gttnet.geometry.triangulation import pseudo_triangulate


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_descriptors_of_rays_to_one_point_are_equal():
    """Rays from either centre to the same 3-D point lie in the same epipolar plane (closed form)."""
    g = np.random.default_rng(0)
    Ca, Cb = np.array([3.0, 0, 1]), np.array([0.0, 3, 1.2])
    X = g.normal(scale=0.5, size=(1, 6, 3))
    da = epipolar_descriptors(_unit(X - Ca), np.ones((1, 6), bool), Ca, Cb)
    db = epipolar_descriptors(_unit(X - Cb), np.ones((1, 6), bool), Ca, Cb)
    np.testing.assert_allclose(da, db, atol=1e-12)
    assert np.allclose(np.linalg.norm(da.reshape(6, 2), axis=-1), 1.0)
    # Another point gives another descriptor; a missing joint gives zeros.
    dc = epipolar_descriptors(_unit(X + 0.3 - Cb), np.array([[True] * 5 + [False]]), Ca, Cb)
    assert np.abs(dc - db).max() > 0.05
    assert np.all(dc[0, -2:] == 0)


def test_pair_costs_match_the_dense_costs(scene_factory):
    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=10, sigma_px=1.0, missing=0.2, seed=1)
    obs, _ = make_view(sample, "none")
    C, r = obs.centers(), obs.rays()
    pt = pseudo_triangulate(C, r, obs.visible, obs.cam_id)
    i, j = np.nonzero(obs.cam_id[:, None] != obs.cam_id[None, :])
    cost, conv, valid, _ = pair_costs(C, r, i, j)
    np.testing.assert_array_equal(np.isinf(cost), np.isinf(pt.cost[i, j]))
    fin = np.isfinite(cost)
    # the dense path ranks pairs by float32 costs: float32 rounding, no more
    np.testing.assert_allclose(cost[fin], pt.cost[i, j][fin], rtol=1e-4, atol=1e-9)
    np.testing.assert_allclose(conv[fin], pt.convergence[i, j][fin], rtol=1e-5)
    np.testing.assert_array_equal(valid, pt.valid[i, j])
    cost32, *_ = pair_costs(C, r, i, j, dtype=np.float32)
    assert np.nanmax(np.abs(cost32[fin] - cost[fin]) / cost[fin].mean()) < 1e-3


def test_candidates_come_from_other_cameras_and_find_the_dense_neighbours(scene_factory):
    sample = scene_factory(n_cameras=4, n_joints=12, frames_per_camera=40, sigma_px=1.0, missing=0.1, seed=2)
    obs, gt = make_view(sample, "none")
    C, r = obs.centers(), obs.rays()
    cand = candidate_partners(C, r, obs.visible, obs.cam_id, per_camera=6)
    assert cand.shape == (obs.n_images, 18)
    assert np.all(obs.cam_id[cand] != obs.cam_id[:, None])
    pt = pseudo_triangulate(C, r, obs.visible, obs.cam_id)
    cp = candidate_pseudo_triangulate(C, r, obs.visible, obs.cam_id, per_camera=6, dtype=np.float64)
    k = 8
    dense = neighbourhoods(pt.cost, sequencing="none", cam_id=obs.cam_id, k=k, order=pt.order)
    sparse = cp.neighbours(k)
    recall = np.mean([len(set(a) & set(b)) / k for a, b in zip(dense, sparse, strict=True)])
    assert recall > 0.8
    # The k-d tree neighbours are near in true time, like the dense ones.
    gap = np.median(np.abs(gt.timestamp_s[sparse] - gt.timestamp_s[:, None]))
    gap_dense = np.median(np.abs(gt.timestamp_s[dense] - gt.timestamp_s[:, None]))
    assert gap < 1.5 * gap_dense
    assert np.median(np.linalg.norm(cp.X_init - gt.points3d, axis=-1)) < 0.02
    # Each slot's cost is the dense cost of that pair (which ranks in float32), sorted ascending per row.
    ok = cp.partners >= 0
    np.testing.assert_allclose(cp.cost[ok], pt.cost[np.nonzero(ok)[0], cp.partners[ok]], rtol=1e-4)
    ranked = np.where(np.isfinite(cp.cost), cp.cost, 1e300)
    assert np.all(np.diff(ranked, axis=1) >= 0)


def test_all_candidates_equals_dense(scene_factory):
    """With as many candidates as images, the candidate path reproduces the dense X_init."""
    sample = scene_factory(n_cameras=3, n_joints=6, frames_per_camera=8, sigma_px=1.0, missing=0.2, seed=4)
    obs, _ = make_view(sample, "none")
    C, r = obs.centers(), obs.rays()
    pt = pseudo_triangulate(C, r, obs.visible, obs.cam_id)
    cp = candidate_pseudo_triangulate(
        C, r, obs.visible, obs.cam_id, per_camera=8, pose_per_camera=0, dtype=np.float64
    )
    np.testing.assert_allclose(cp.X_init, pt.X_init, atol=1e-9)


def test_prepare_inputs_kdtree_neighbours(scene_factory):
    pytest.importorskip("torch")
    from gttnet.model.inputs import prepare_inputs

    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=12, sigma_px=1.0, seed=5)
    obs, _ = make_view(sample, "none")
    seq = prepare_inputs(obs, k=6, candidates="kdtree")
    nbr = seq.nbr.numpy()
    assert nbr.shape == (obs.n_images, 6)
    assert np.all(obs.cam_id[nbr] != obs.cam_id[:, None])
    with pytest.raises(ValueError, match="candidates"):
        prepare_inputs(obs, k=6, candidates="bogus")


@pytest.mark.parametrize("method", ["pseudo", "dloe"])
def test_methods_take_the_kdtree_search(scene_factory, method):
    from gttnet.baselines import reconstruct
    from gttnet.evaluate.metrics import mpjpe_mm

    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=30, sigma_px=1.0, missing=0.1, seed=8)
    obs, gt = make_view(sample, "none")
    dense = reconstruct(obs, method, candidates="dense")
    tree = reconstruct(obs, method, candidates="kdtree")
    assert tree.points3d.shape == dense.points3d.shape and np.all(np.isfinite(tree.points3d))
    e_dense, e_tree = mpjpe_mm(dense.points3d, gt.points3d), mpjpe_mm(tree.points3d, gt.points3d)
    assert e_tree < 1.2 * e_dense + 1.0
    with pytest.raises(ValueError, match="candidates"):
        reconstruct(obs, method, candidates="bogus")
