"""Tests of pseudo-triangulation: ray-ray closest points, pair cost, validity, neighbour order and X_init."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gttdata.capture.views import make_view
from gttnet.errors import GttNetError
from gttnet.geometry.triangulation import closest_points_on_rays, pseudo_triangulate


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_closest_points_skew_rays_closed_form():
    s, t, gap = closest_points_on_rays(
        np.zeros(3), _unit([1, 0, 0]), np.array([2.0, -1, 1]), _unit([0, 1, 0])
    )
    assert (float(s), float(t), float(gap)) == pytest.approx((2.0, 1.0, 1.0))


def test_closest_points_intersecting_and_parallel():
    P = np.array([0.3, -0.2, 1.5])
    C = np.array([[1.0, 2, 0], [-2.0, 0.5, 3]])
    s, t, gap = closest_points_on_rays(C[0], _unit(P - C[0]), C[1], _unit(P - C[1]))
    assert float(gap) < 1e-12
    np.testing.assert_allclose(C[0] + s * _unit(P - C[0]), P, atol=1e-12)
    _, _, gap_par = closest_points_on_rays(C[0], _unit([0, 0, 1]), C[1], _unit([0, 0, 1]))
    assert np.isnan(gap_par)


def test_pair_cost_of_meeting_and_skew_rays():
    # Joint 0 rays meet; joint 1 rays are skew with gap 1 at depths 2 and 1 -> error 1 / 3.
    C = np.array([[0.0, 0, 0], [2.0, -1, 1]])
    P = np.array([1.0, 1.0, 1.0])
    r = np.stack([[_unit(P - C[0]), _unit([1, 0, 0])], [_unit(P - C[1]), _unit([0, 1, 0])]])
    pt = pseudo_triangulate(C, r, np.ones((2, 2), bool), np.array([0, 1]))
    assert pt.cost[0, 1] == pytest.approx((0.0 + 1.0 / 3.0) / 2)
    assert pt.cost[0, 1] == pytest.approx(pt.cost[1, 0])
    assert np.isinf(pt.cost[0, 0])
    np.testing.assert_allclose(pt.X_init[:, 0], [P, P], atol=1e-12)
    np.testing.assert_allclose(pt.X_init[0, 1], [2.0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(pt.X_init[1, 1], [2.0, 0, 1], atol=1e-12)
    assert pt.convergence[0, 1] == pytest.approx((_unit(P - C[0]) @ _unit(P - C[1]) + 0.0) / 2)
    assert pt.source.tolist() == [[1, 1], [0, 0]]


def test_negative_depth_skips_that_joint_only():
    # Joint 1's closest points lie behind camera 0: invalid for this pair, without NaN, other joint kept.
    C = np.array([[0.0, 0, 0], [2.0, -1, 1]])
    r = np.stack([[_unit([1, 0, 0]), _unit([-1, 0, 0])], [_unit([0, 1, 0]), _unit([0, 1, 0])]])
    pt = pseudo_triangulate(C, r, np.ones((2, 2), bool), np.array([0, 1]))
    assert pt.valid[0, 1].tolist() == [True, False]
    assert pt.cost[0, 1] == pytest.approx(1.0 / 3.0)
    assert np.all(np.isfinite(pt.X_init))
    # Joint 1 was valid for no pair: filled, then put back on its own ray at a positive depth.
    d = pt.X_init[:, 1] - C
    assert np.linalg.norm(np.cross(d, r[:, 1]), axis=-1).max() < 1e-12
    assert np.all(np.einsum("nk,nk->n", d, r[:, 1]) > 0)


def test_all_joints_invalid_gives_infinite_cost_and_same_camera_inf():
    C = np.array([[0.0, 0, 0], [2.0, -1, 1], [0.0, 0.5, 0], [2.0, -1, 1]])
    r = np.stack([[_unit([1, 0, 0])], [_unit([0, -1, 0])], [_unit([1, 0, 0.1])], [_unit([0, 1, 0])]])
    pt = pseudo_triangulate(C, r, np.ones((4, 1), bool), np.array([0, 1, 0, 2]))
    assert pt.cost[0, 3] == pytest.approx(1.0 / 3.0)
    assert np.isinf(pt.cost[0, 1])  # t < 0
    assert np.isinf(pt.cost[0, 2]) and np.isinf(pt.cost[2, 0])  # same camera
    assert not pt.valid[0, 2].any()


def test_missing_joint_filled_from_best_ranked_neighbour(toy_sample):
    obs, _ = make_view(toy_sample, "none")
    vis = obs.visible.copy()
    vis[0, 2] = False
    rays = obs.rays() * vis[..., None]
    pt = pseudo_triangulate(obs.centers(), rays, vis, obs.cam_id, min_angle_deg=0.0)
    best = next(m for m in pt.order[0] if pt.source[m, 2] >= 0 and np.isfinite(pt.cost[0, m]))
    np.testing.assert_array_equal(pt.X_init[0, 2], pt.X_init[best, 2])
    assert pt.source[0, 2] == -1


def test_x_init_on_rays_and_close_to_truth(scene_factory):
    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=20, sigma_px=1.0, missing=0.2, seed=3)
    obs, gt = make_view(sample, "none")
    C, r = obs.centers(), obs.rays()
    pt = pseudo_triangulate(C, r, obs.visible, obs.cam_id)
    assert np.all(np.isfinite(pt.X_init))
    off_ray = np.linalg.norm(np.cross(pt.X_init - C[:, None], r), axis=-1)
    assert off_ray[obs.visible].max() < 1e-9
    err = np.linalg.norm(pt.X_init - gt.points3d, axis=-1)
    assert np.median(err[obs.visible]) < 0.02
    assert np.median(err[~obs.visible]) < 0.05
    np.testing.assert_array_equal(np.isinf(pt.cost), ~pt.valid.any(-1))
    finite_first = np.take_along_axis(np.isfinite(pt.cost), pt.order, axis=1)
    assert np.all(np.diff(finite_first.astype(int), axis=1) <= 0)
    ranked = np.take_along_axis(pt.cost, pt.order, axis=1)
    assert np.all(np.diff(np.where(np.isfinite(ranked), ranked, 1e300), axis=1) >= 0)


def test_a_rig_far_from_the_origin_keeps_its_costs(scene_factory):
    """The float32 pair costs are formed about the rig's centre: moving the world 100 km leaves them alone."""
    sample = scene_factory(n_cameras=4, n_joints=8, frames_per_camera=20, sigma_px=1.0, missing=0.2, seed=3)
    obs, _ = make_view(sample, "none")
    C, r = obs.centers(), obs.rays()
    near = pseudo_triangulate(C, r, obs.visible, obs.cam_id)
    far = pseudo_triangulate(C + np.array([1e5, -2e5, 50.0]), r, obs.visible, obs.cam_id)
    fin = np.isfinite(near.cost)
    np.testing.assert_array_equal(np.isfinite(far.cost), fin)
    np.testing.assert_allclose(far.cost[fin], near.cost[fin], rtol=1e-3, atol=1e-7)
    np.testing.assert_allclose(far.X_init - np.array([1e5, -2e5, 50.0]), near.X_init, atol=1e-6)


def test_demotion_moves_near_parallel_neighbours_back():
    # Image 1 is a near-parallel view (2 degrees from image 0), image 2 a wide-baseline one.
    P = np.array([0.0, 0.0, 2.0])
    C = np.array([[0.0, 0, 0], [0.07, 0, 0], [2.0, 0, 2.0]])
    rng = np.random.default_rng(0)
    pts = P + 0.1 * rng.normal(size=(4, 3))
    r = _unit(pts[None] - C[:, None])
    r[2] = _unit(r[2] + 0.01 * rng.normal(size=(4, 3)))  # image 2 has a worse cost
    vis = np.ones((3, 4), bool)
    plain = pseudo_triangulate(C, r, vis, np.arange(3), min_angle_deg=0.0)
    demoted = pseudo_triangulate(C, r, vis, np.arange(3), min_angle_deg=5.0)
    assert (plain.source[0] == 1).all() and (demoted.source[0] == 2).all()
    assert plain.order[0, 0] == demoted.order[0, 0] == 1  # the neighbour order itself is not demoted
    np.testing.assert_array_equal(plain.cost, demoted.cost)


def test_permutation_equivariance(toy_sample):
    obs, _ = make_view(toy_sample, "none")
    C, r, v, cam = obs.centers(), obs.rays(), obs.visible, obs.cam_id
    perm = np.random.default_rng(1).permutation(obs.n_images)
    a = pseudo_triangulate(C, r, v, cam)
    b = pseudo_triangulate(C[perm], r[perm], v[perm], cam[perm])
    np.testing.assert_allclose(b.cost, a.cost[np.ix_(perm, perm)])
    np.testing.assert_allclose(b.X_init, a.X_init[perm], atol=1e-12)


def test_blocking_does_not_change_results(toy_sample):
    obs, _ = make_view(toy_sample, "none")
    a = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id, block_rows=5)
    b = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id, block_rows=1000)
    np.testing.assert_array_equal(a.cost, b.cost)
    np.testing.assert_array_equal(a.valid, b.valid)


def test_rays_are_normalised_and_bad_visible_rays_raise():
    C = np.array([[0.0, 0, 0], [2.0, -1, 1]])
    r = np.array([[[3.0, 0, 0]], [[0.0, 0.5, 0]]])
    pt = pseudo_triangulate(C, r, np.ones((2, 1), bool), np.array([0, 1]))
    assert pt.cost[0, 1] == pytest.approx(1.0 / 3.0)
    r[1, 0] = np.nan
    with pytest.raises(ValueError, match="joint 0 of image 1"):
        pseudo_triangulate(C, r, np.ones((2, 1), bool), np.array([0, 1]))


def test_errors():
    C = np.zeros((2, 3))
    r = np.ones((2, 1, 3)) / np.sqrt(3)
    with pytest.raises(ValueError, match="rays"):
        pseudo_triangulate(C, r[:1], np.ones((2, 1), bool), np.array([0, 1]))
    with pytest.raises(GttNetError, match="no triangulable joint"):
        pseudo_triangulate(np.array([[0.0, 0, 0], [1.0, 0, 0]]), r, np.ones((2, 1), bool), np.array([0, 0]))


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 40), st.integers(1, 4), st.floats(0.0, 0.3))
def test_first_in_rank_matches_a_search_over_all_ranks(seed, n, j, density):
    # The head-first search gives the full search's answer wherever the joint is needed.
    from gttnet.geometry.triangulation import _first_in_rank

    g = np.random.default_rng(seed)
    table = g.uniform(size=(n, n, j)) < density  # qualifies[i, k, p]
    needed = g.uniform(size=(n, j)) < 0.7
    first, found = _first_in_rank(lambda rows, ks: table[rows[:, None], ks[None, :]], needed, head=4)
    ref_found = table.any(axis=1)
    ref_first = np.argmax(table, axis=1)
    np.testing.assert_array_equal(found[needed], ref_found[needed])
    np.testing.assert_array_equal(first[needed & ref_found], ref_first[needed & ref_found])
