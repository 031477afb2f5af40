"""Tests of the DLOE X-step: closed forms, agreement with the dense reference, gradients, guards."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gttdata.capture.views import make_view
from gttnet.geometry.triangulation import closest_points_on_rays, pseudo_triangulate
from gttnet.solvers import (
    DLOESolver,
    SingularStructureError,
    noise_aware_lambda2,
    solve_structure,
    solve_structure_dense,
    structure_energy,
)

F64 = torch.float64
METHODS = ("dense", "sparse")


def _random_case(
    seed: int = 0, n: int = 9, j: int = 3, missing: tuple[tuple[int, int], ...] = ((0, 1), (4, 2))
):
    """Cameras 3 m around the origin looking at points near it; a random connected non-negative affinity."""
    g = np.random.default_rng(seed)
    C = g.normal(size=(n, 3))
    C = 3.0 * C / np.linalg.norm(C, axis=-1, keepdims=True)
    X = 0.3 * g.normal(size=(n, j, 3))
    r = X - C[:, None]
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    vis = np.ones((n, j), bool)
    for i, p in missing:
        vis[i, p] = False
    A = g.uniform(0.1, 1.0, (n, n)) * (g.uniform(size=(n, n)) < 0.35)
    A += np.diag(np.full(n - 1, 0.5), 1)  # a chain keeps the graph connected
    np.fill_diagonal(A, 0.0)
    return torch.tensor(A, dtype=F64), C, r, vis


def _skew_pair():
    C = np.array([[0.0, 0, 0], [2.0, -1, 1]])
    r = np.array([[[1.0, 0, 0]], [[0.0, 1, 0]]])
    return C, r


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("lambda1", [0.0, 0.1, 2.0])
def test_two_images_give_ray_closest_points(method, lambda1):
    # N = 2, A symmetric: M is a multiple of the path Laplacian, so the energy is |X0 - X1|^2 and the
    # pinned minimiser is the common perpendicular of the two rays.
    C, r = _skew_pair()
    A = torch.tensor([[0.0, 1.0], [1.0, 0.0]], dtype=F64)
    X = solve_structure(A, C, r, np.ones((2, 1), bool), lambda1=lambda1, method=method)
    s, t, gap = closest_points_on_rays(C[0], r[0, 0], C[1], r[1, 0])
    assert float(gap) == pytest.approx(1.0)
    np.testing.assert_allclose(X[0, 0].numpy(), C[0] + s * r[0, 0], atol=1e-12)
    np.testing.assert_allclose(X[1, 0].numpy(), C[1] + t * r[1, 0], atol=1e-12)


@pytest.mark.parametrize("method", METHODS)
def test_missing_image_is_filled_at_the_meeting_point(method):
    # Rays of images 0 and 1 meet at P; image 2 misses the joint and is linked to both: X = P everywhere.
    P = np.array([0.2, -0.1, 1.0])
    C = np.array([[0.0, -3, 1], [3.0, 0, 1], [0, 3, 1]])
    r = (P - C)[:, None, :] / np.linalg.norm(P - C, axis=-1)[:, None, None]
    vis = np.array([[True], [True], [False]])
    A = torch.tensor([[0, 1, 1], [1, 0, 1], [1, 1, 0]], dtype=F64)
    X = solve_structure(A, C, r, vis, method=method)
    np.testing.assert_allclose(X[:, 0].numpy(), np.tile(P, (3, 1)), atol=1e-9)


@pytest.mark.parametrize("method", METHODS)
def test_pinned_solution_is_stationary(method):
    # Optimality of the pinned problem: the Laplacian energy's gradient is orthogonal to the ray for
    # observed joints (only the depth is free) and zero for missing ones.
    A, C, r, vis = _random_case()
    X = solve_structure(A, C, r, vis, method=method).requires_grad_(True)
    (g,) = torch.autograd.grad(structure_energy(A, X, lambda1=0.1), X)
    rt = torch.tensor(r)
    along = (g * rt).sum(-1, keepdim=True) * rt
    free = torch.where(torch.tensor(vis)[..., None], along, g)
    assert float(g.abs().max()) > 1e-3  # the constraint forces are not trivially zero
    assert float(free.abs().max()) < 1e-12
    rays_ok = torch.linalg.cross(X.detach() - torch.tensor(C)[:, None], rt).norm(dim=-1)
    assert float(rays_ok[torch.tensor(vis)].max()) < 1e-10


@pytest.mark.parametrize("method", METHODS)
def test_finite_lambda2_is_stationary(method):
    A, C, r, vis = _random_case(seed=3)
    lam2 = 5.0
    X = solve_structure(A, C, r, vis, lambda2=lam2, method=method).requires_grad_(True)
    e = structure_energy(A, X, lambda1=0.1, centers=C, rays=r, visible=vis, lambda2=lam2)
    (g,) = torch.autograd.grad(e, X)
    assert float(g.abs().max()) < 1e-12


@pytest.mark.parametrize("lambda2", [None, 1e6])
@pytest.mark.parametrize("method", METHODS)
def test_agrees_with_dense_reference(method, lambda2):
    # lambda2 = 1e10 in the reference leaves ~1e-6 relative error from conditioning (cond(H) ~ 1e10 cond(M));
    # compare the pinned limit there, and the same finite lambda2 where the reference is well conditioned.
    A, C, r, vis = _random_case(seed=1)
    ref = solve_structure_dense(A, C, r, vis, lambda2=1e10 if lambda2 is None else lambda2)
    X = solve_structure(A, C, r, vis, lambda2=lambda2, method=method)
    assert float((X - ref).norm() / ref.norm()) < 1e-4


@pytest.mark.parametrize("lambda2", [None, 3.0])
@pytest.mark.parametrize("method", METHODS)
def test_gradcheck_wrt_affinity(method, lambda2):
    # Strictly positive A (the Laplacians ignore its diagonal) so finite differences stay non-negative.
    A, C, r, vis = _random_case(seed=2, n=5, j=2, missing=((1, 0),))
    A = (A + 0.05).requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda a: solve_structure(a, C, r, vis, lambda2=lambda2, method=method), (A,), eps=1e-6, atol=1e-6
    )


def test_gradcheck_wrt_rays_dense():
    A, C, r, vis = _random_case(seed=12, n=4, j=1, missing=((2, 0),))
    rays = torch.tensor(r).requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda rr: solve_structure(A, C, rr, vis, method="dense"), (rays,), eps=1e-6, atol=1e-6
    )
    with pytest.raises(ValueError, match="ray gradients"):
        solve_structure(A, C, rays, vis, method="sparse")


def test_gradcheck_dense_reference():
    A, C, r, vis = _random_case(seed=2, n=4, j=2, missing=((1, 0),))
    A = (A + 0.05).requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda a: solve_structure_dense(a, C, r, vis, lambda2=3.0), (A,), eps=1e-6, atol=1e-6
    )


def test_sparse_and_dense_gradients_match():
    A, C, r, vis = _random_case(seed=4, n=12, j=3)
    w = torch.randn(12, 3, 3, dtype=F64, generator=torch.Generator().manual_seed(0))
    grads = []
    for method in METHODS:
        a = A.clone().requires_grad_(True)
        (solve_structure(a, C, r, vis, method=method) * w).sum().backward()
        grads.append(a.grad)
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("missing", [0.0, 0.2])
def test_true_temporal_chain_reconstructs_noise_free_capture(scene_factory, method, missing):
    sample = scene_factory(n_cameras=4, n_joints=6, frames_per_camera=12, missing=missing, seed=5)
    obs, gt = make_view(sample, "none")
    A = torch.tensor(gt.affinity_binary())  # ground truth is used only as the test's affinity
    X = solve_structure(A, obs.centers(), obs.rays(), obs.visible, method=method).numpy()
    err = np.linalg.norm(X - gt.points3d, axis=-1)
    assert err.mean() < 1e-3
    if missing:
        assert err[~obs.visible].mean() < 3e-3  # missing joints filled by the chain, not left anywhere


def test_batched_affinity_matches_loop():
    A, C, r, vis = _random_case(seed=6)
    A2 = torch.stack([A, A.T.contiguous() * 0.5])
    Xb = solve_structure(A2, C, r, vis, method="dense")
    assert Xb.shape == (2, 9, 3, 3)
    for b in range(2):
        torch.testing.assert_close(Xb[b], solve_structure(A2[b], C, r, vis, method="sparse"))


def test_unobserved_joint_raises_without_prior_and_uses_it_with():
    A, C, r, vis = _random_case(seed=7)
    vis[:, 2] = False
    with pytest.raises(SingularStructureError, match="joint 2"):
        solve_structure(A, C, r, vis)
    prior = np.zeros((9, 3, 3))
    prior[:, 2] = [0.1, 0.2, 0.3]
    for method in METHODS:
        X = solve_structure(A, C, r, vis, x_prior=prior, method=method)
        assert torch.isfinite(X).all()
        np.testing.assert_allclose(X[:, 2].numpy(), prior[:, 2], atol=1e-6)


def test_disconnected_single_image_raises():
    A, C, r, vis = _random_case(seed=8)
    A[0, :] = 0.0
    A[:, 0] = 0.0  # image 0 alone: its depth is free
    with pytest.raises(SingularStructureError, match="component of 1 images"):
        solve_structure(A, C, r, vis)
    X = solve_structure(A, C, r, vis, x_prior=np.zeros((9, 3, 3)), method="dense")
    assert torch.isfinite(X).all()


def test_input_validation():
    A, C, r, vis = _random_case()
    with pytest.raises(ValueError, match="shape"):
        solve_structure(A[:, :5], C, r, vis)
    with pytest.raises(ValueError, match="method"):
        solve_structure(A, C, r, vis, method="qr")
    with pytest.raises(ValueError, match="non-negative"):
        solve_structure(-A, C, r, vis)
    with pytest.raises(ValueError, match="> 0"):
        noise_aware_lambda2(0.0, 1000.0, 3.0)
    r_bad = r.copy()
    r_bad[2, 1] = 0.0
    with pytest.raises(ValueError, match="non-zero ray"):
        solve_structure(A, C, r_bad, vis)
    r_bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="finite"):
        solve_structure(A, C, r_bad, vis)
    # Rays are normalised: scaled rays give the same structure.
    torch.testing.assert_close(solve_structure(A, C, 2.5 * r, vis), solve_structure(A, C, r, vis))


def test_float32_close_to_float64():
    A, C, r, vis = _random_case(seed=9)
    X64 = solve_structure(A, C, r, vis, method="dense")
    X32 = solve_structure(A.float(), C, r, vis, method="dense")
    assert X32.dtype == torch.float32
    torch.testing.assert_close(X32.double(), X64, rtol=0, atol=1e-4)
    assert solve_structure(A.float(), C, r, vis, method="sparse").dtype == torch.float32


def test_module_matches_function_and_auto_picks_sparse_for_large_sparse_a(scene_factory, monkeypatch):
    import gttnet.solvers.xstep as xstep

    calls = []
    real = xstep.solve_sparse
    monkeypatch.setattr(xstep, "solve_sparse", lambda *a: calls.append(1) or real(*a))
    sample = scene_factory(n_cameras=4, n_joints=3, frames_per_camera=55, seed=2)  # N = 220
    obs, gt = make_view(sample, "full")
    A = torch.tensor(gt.affinity_binary())
    X = DLOESolver(lambda1=0.1)(A, obs.centers(), obs.rays(), obs.visible)
    assert calls == [1]
    torch.testing.assert_close(X, solve_structure(A, obs.centers(), obs.rays(), obs.visible, method="dense"))
    solve_structure(A + 0.01, obs.centers(), obs.rays(), obs.visible)  # dense A: dense path
    assert calls == [1]


def test_noise_aware_lambda2_beats_pinning_under_noise(scene_factory):
    sample = scene_factory(n_cameras=4, n_joints=6, frames_per_camera=15, sigma_px=5.0, seed=11)
    obs, gt = make_view(sample, "full")
    A = torch.tensor(gt.affinity_binary())
    lam2 = noise_aware_lambda2(5.0, 1000.0, 3.0)
    errs = [
        np.linalg.norm(
            solve_structure(A, obs.centers(), obs.rays(), obs.visible, lambda2=l2).numpy() - gt.points3d,
            axis=-1,
        ).mean()
        for l2 in (None, lam2)
    ]
    assert errs[1] < errs[0]


def test_x_init_prior_keeps_well_posed_solution(scene_factory):
    sample = scene_factory(n_cameras=3, n_joints=4, frames_per_camera=8, seed=1)
    obs, gt = make_view(sample, "none")
    pt = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id)
    A = torch.tensor(gt.affinity_binary())
    X0 = solve_structure(A, obs.centers(), obs.rays(), obs.visible)
    X1 = solve_structure(A, obs.centers(), obs.rays(), obs.visible, x_prior=pt.X_init)
    assert float((X1 - X0).abs().max()) < 1e-4


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
@pytest.mark.parametrize("lambda2", [None, 1e6])
def test_cuda_matches_cpu(lambda2):
    A, C, r, vis = _random_case(seed=10)
    X_cpu = solve_structure(A, C, r, vis, lambda2=lambda2, method="dense")
    a = A.cuda().requires_grad_(True)
    X = solve_structure(a, C, r, vis, lambda2=lambda2)
    assert X.device.type == "cuda"
    torch.testing.assert_close(X.cpu(), X_cpu, rtol=1e-6, atol=1e-9)  # cond(H) ~ lambda2 for finite lambda2
    X.sum().backward()
    assert torch.isfinite(a.grad).all()
    if lambda2 is None:  # float32 cannot resolve a 1e6 ray weight against O(1) Laplacian terms
        X32 = solve_structure(A.float().cuda(), C, r, vis, lambda2=lambda2)
        torch.testing.assert_close(X32.double().cpu(), X_cpu, rtol=0, atol=1e-3)


def test_structure_diagonal_is_the_diagonal_of_the_structure_matrix():
    from gttnet.solvers.xstep import _structure_diagonal, _structure_matrix

    A = torch.rand(2, 7, 7, dtype=torch.float64) * (torch.rand(2, 7, 7, dtype=torch.float64) > 0.5)
    A[0, 2, 2] = 0.4  # a non-zero diagonal is covered too
    ref = torch.diagonal(_structure_matrix(A, 0.1), dim1=-2, dim2=-1)
    torch.testing.assert_close(_structure_diagonal(A, 0.1), ref, rtol=1e-12, atol=1e-12)


def test_dense_factor_reports_a_singular_system_as_singular_structure():
    # It used to surface as torch's RuntimeError "U[k,k] is zero ..." and end a training run.
    from gttnet.errors import SingularStructureError
    from gttnet.solvers._system import _factor

    H = torch.eye(3).repeat(2, 1, 1)
    H[1, 2, 2] = 0.0
    with pytest.warns(RuntimeWarning, match="not numerically positive definite"):
        with pytest.raises(SingularStructureError, match="1 of 2 joint systems"):
            _factor(H)


@pytest.mark.parametrize("seed", range(6))
def test_sparse_assembly_matches_the_entrywise_definition(seed):
    # Joints observed everywhere (one unknown per image) and joints with extra slots, with and without
    # ray-weight blocks W, in a fill-reducing image order: every active slot pair (a at image n, b at m)
    # holds M[n, m] v_a . v_b, plus v_a^T W_n v_b when n = m, in canonical CSC form.
    import scipy.sparse as sp

    from gttnet.solvers._sparse import _assemble, _image_order

    rng = np.random.default_rng(seed)
    n, j = 25, 4
    A = (rng.random((n, n)) < 0.2) * rng.random((n, n))
    np.fill_diagonal(A, 0.0)
    A[0] = A[:, 0] = 0.0  # an image without links
    As = sp.csr_matrix(A)
    L = sp.diags(np.asarray(As.sum(1)).ravel()) - As
    M = (L.T @ L).tocsr()
    act = np.zeros((j, n, 3), bool)
    act[..., 0] = True
    act[2:, rng.random(n) < 0.3, 1:] = True  # joints 0, 1 plain; 2, 3 with extra slots
    V = rng.normal(size=(j, n, 3, 3)) * act[..., None]
    W = None if seed % 2 else rng.normal(size=(j, n, 3, 3))
    H, pos = _assemble(M, V, act, W, order=_image_order(M))
    assert H.has_canonical_format
    assert sorted(pos[act].tolist()) == list(range(int(act.sum())))
    Hd, Md = H.toarray(), M.toarray()
    for jj, nn, a in np.argwhere(act):
        for mm, b in np.argwhere(act[jj]):
            want = Md[nn, mm] * V[jj, nn, a] @ V[jj, mm, b]
            if W is not None and nn == mm:
                want += V[jj, nn, a] @ W[jj, nn] @ V[jj, nn, b]
            assert Hd[pos[jj, nn, a], pos[jj, mm, b]] == pytest.approx(want, abs=1e-12)
    # no entries couple different joints
    owner = np.empty(int(act.sum()), dtype=int)
    owner[pos[act]] = np.argwhere(act)[:, 0]
    r, c = H.nonzero()
    assert np.all(owner[r] == owner[c])


@pytest.mark.parametrize("lambda2", [None, 30.0, "per-image"])
@pytest.mark.parametrize("prior", [False, True])
def test_numpy_xstep_matches_the_torch_paths(lambda2, prior):
    # The classical methods' torch-free X-step solves the same systems as both torch paths.
    from gttnet.solvers.numpy_xstep import solve_structure_np

    A, C, r, vis = _random_case(seed=12, n=14, j=4, missing=((0, 1), (4, 2), (5, 2), (9, 0)))
    lam = np.linspace(5.0, 50.0, 14) if lambda2 == "per-image" else lambda2
    kw = {"lambda1": 0.05, "lambda2": lam, "x_prior": 0.1 * np.ones((14, 4, 3)) if prior else None}
    X = solve_structure_np(A.numpy(), C, 1.7 * r, vis, **kw)
    assert isinstance(X, np.ndarray) and X.shape == (14, 4, 3)
    for method in ("sparse", "dense"):
        ref = solve_structure(A, C, r, vis, method=method, **kw).numpy()
        np.testing.assert_allclose(X, ref, rtol=0, atol=1e-9)
    # batched inputs give the per-item solutions
    Xb = solve_structure_np(np.stack([A.numpy(), 2.0 * A.numpy()]), C, r, vis, **kw)
    np.testing.assert_allclose(Xb[0], X, rtol=0, atol=1e-12)
    ref2 = solve_structure(2.0 * A, C, r, vis, method="sparse", **kw).numpy()
    np.testing.assert_allclose(Xb[1], ref2, rtol=0, atol=1e-9)


def test_numpy_xstep_guards():
    from gttnet.solvers.numpy_xstep import solve_structure_np

    A, C, r, vis = _random_case(seed=3)
    A = A.numpy()
    with pytest.raises(ValueError, match="non-negative"):
        solve_structure_np(-A, C, r, vis)
    with pytest.raises(ValueError, match="expected centers"):
        solve_structure_np(A[:5, :5], C, r, vis)
    with pytest.raises(ValueError, match="lambda2"):
        solve_structure_np(A, C, r, vis, lambda2=-1.0)
    r_bad = r.copy()
    r_bad[2, 1] = 0.0
    with pytest.raises(ValueError, match="non-zero ray"):
        solve_structure_np(A, C, r_bad, vis)
    # one camera sees joint 0 in a component cut off from the rest: its depth is free
    C2, r2 = _skew_pair()
    with pytest.raises(SingularStructureError):
        solve_structure_np(np.zeros((2, 2)), C2, r2, np.ones((2, 1), bool))
