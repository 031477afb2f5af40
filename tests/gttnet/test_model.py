"""GTT-Net modules: shapes, invariances, gradients, and ground truth never reaching inference."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from gttdata.capture.views import make_view
from gttnet.errors import ModelError
from gttnet.model import inference
from gttnet.model.affinity import AffinityHead, sparse_affinity
from gttnet.model.continuous_conv import ContinuousConv
from gttnet.model.inputs import prepare_inputs, random_rotation
from gttnet.model.network import GTTNetConfig, build_model
from gttnet.model.norm import PointSetNorm
from gttnet.model.patches import build_patches, patch_index
from gttnet.model.pointnet import PointNetStream
from gttnet.model.unet import ContinuousConvUNet


def _random_nbr(n: int, k: int, gen: torch.Generator, *, pad_rows: int = 0) -> torch.Tensor:
    nbr = torch.stack([torch.randperm(n - 1, generator=gen)[:k] for _ in range(n)])
    nbr = nbr + (nbr >= torch.arange(n)[:, None]).long()  # skip self
    nbr[:pad_rows, k // 2 :] = -1
    return nbr


# --- patches -------------------------------------------------------------------------------------


def test_patches_slot0_is_self_and_pads_masked():
    x = torch.randn(5, 4, 3)
    nbr = torch.tensor([[1, 2], [0, -1], [3, 4], [2, -1], [0, 1]])
    p, m = build_patches(x, nbr)
    assert p.shape == (5, 3, 4, 3) and m.shape == (5, 3)
    assert torch.equal(p[:, 0], x)
    assert torch.equal(p[0, 2], x[2])
    assert m[1].tolist() == [True, True, False] and torch.count_nonzero(p[1, 2]) == 0


def test_patches_reject_bad_shapes():
    with pytest.raises(ValueError, match=r"\(N, J, 3\)"):
        build_patches(torch.zeros(4, 3), torch.zeros(4, 2, dtype=torch.long))
    with pytest.raises(ValueError, match="rows"):
        build_patches(torch.zeros(4, 2, 3), torch.zeros(3, 2, dtype=torch.long))
    with pytest.raises(ValueError, match=r"\(N, K\)"):
        patch_index(torch.zeros(4, dtype=torch.long))


# --- continuous convolution, norm, U-Net ---------------------------------------------------------


def test_continuous_conv_shapes_and_pads_ignored():
    gen = torch.Generator().manual_seed(0)
    conv = ContinuousConv(6, 4, n_slots=4, hidden=8)
    x = torch.randn(7, 6, 3, generator=gen)
    nbr = _random_nbr(7, 3, gen, pad_rows=2)
    index, mask = patch_index(nbr)
    out, slots = conv(x, index, mask)
    assert out.shape == (7, 4, 3) and slots.shape == (7, 4, 4, 3)
    with pytest.raises(ValueError, match=r"\(N, 6, 3\)"):
        conv(torch.randn(7, 5, 3), index, mask)


def test_continuous_conv_equivariant_to_image_order():
    """Relabelling the images (as the 'none' condition does) only permutes the outputs."""
    gen = torch.Generator().manual_seed(1)
    conv = ContinuousConv(5, 3, n_slots=4, hidden=8).double()
    x = torch.randn(9, 5, 3, generator=gen, dtype=torch.float64)
    nbr = _random_nbr(9, 3, gen)
    perm = torch.randperm(9, generator=gen)
    inv = torch.empty_like(perm)
    inv[perm] = torch.arange(9)
    out, _ = conv(x, *patch_index(nbr))
    out_p, _ = conv(x[perm], *patch_index(inv[nbr[perm]]))
    torch.testing.assert_close(out_p, out[perm])


def test_slot_rank_input():
    """slot_rank appends the one-hot neighbour rank to the slot MLP input."""
    conv = ContinuousConv(4, 2, n_slots=4, hidden=8, slot_rank=True)
    assert conv.slot_mlp[0].in_features == 3 * 4 + 4
    gen = torch.Generator().manual_seed(4)
    out, _ = conv(torch.randn(6, 4, 3, generator=gen), *patch_index(_random_nbr(6, 3, gen)))
    assert out.shape == (6, 2, 3)


@pytest.mark.parametrize("slot_rank", [False, True])
def test_continuous_conv_matches_direct_formulation(slot_rank):
    """The channel-major forward (slot MLP applied per image) equals the direct one, values and gradients."""
    gen = torch.Generator().manual_seed(5)
    conv = ContinuousConv(7, 3, n_slots=5, hidden=6, slot_rank=slot_rank).double()
    x = torch.randn(11, 7, 3, generator=gen, dtype=torch.float64, requires_grad=True)
    index, mask = patch_index(_random_nbr(11, 4, gen, pad_rows=3))
    out, slots = conv(x, index, mask)
    ref_out, ref_slots = conv._forward_reference(x, index, mask)
    torch.testing.assert_close(out, ref_out)
    torch.testing.assert_close(slots, ref_slots)
    w = torch.randn(ref_slots.shape, generator=gen, dtype=torch.float64)
    grads = torch.autograd.grad((out**2).sum() + (slots * w).sum(), [x, *conv.parameters()])
    ref = torch.autograd.grad((ref_out**2).sum() + (ref_slots * w).sum(), [x, *conv.parameters()])
    for g, r in zip(grads, ref, strict=True):
        torch.testing.assert_close(g, r)


def test_point_set_norm_invariances():
    norm = PointSetNorm(4).double()
    x = torch.randn(6, 4, 3, dtype=torch.float64)
    seg = torch.tensor([0, 0, 0, 1, 1, 1])
    y = norm(x, seg, 2)
    shifted = x + torch.randn(6, 1, 3, dtype=torch.float64)  # per-image translation
    torch.testing.assert_close(norm(shifted, seg, 2), y)
    scaled = x.clone()
    scaled[3:] *= 7.0  # scaling one whole sequence leaves both unchanged
    torch.testing.assert_close(norm(scaled, seg, 2), y, atol=1e-4, rtol=1e-4)  # eps in the variance


def test_unet_levels_and_paper_size():
    unet = ContinuousConvUNet(31, (16, 8, 4, 4), n_slots=21, hidden=16)
    n_params = sum(p.numel() for p in unet.parameters())
    assert 12_000 < n_params < 20_000  # the paper's "about 16k"
    gen = torch.Generator().manual_seed(2)
    x = torch.randn(30, 31, 3, generator=gen)
    index, mask = patch_index(_random_nbr(30, 20, gen))
    out = unet(x, index, mask, torch.zeros(30, dtype=torch.long), 1)
    assert out.bottleneck.shape == (30, 4, 3) and out.bottleneck_slots.shape == (30, 21, 4, 3)
    assert out.output.shape == x.shape
    assert [d.shape[1] for d, _ in out.pairs] == [31, 16, 8, 4]
    assert all(d.shape == e.shape for d, e in out.pairs)


# --- affinity head -------------------------------------------------------------------------------


@pytest.mark.parametrize("mode", ["paper", "reference"])
def test_affinity_head_values_and_topq(mode):
    gen = torch.Generator().manual_seed(3)
    head = AffinityHead(mode, top_q=2)
    feats = torch.randn(8, 4, 3, generator=gen)
    slots = torch.randn(8, 5, 4, 3, generator=gen)
    nbr = _random_nbr(8, 4, gen, pad_rows=2)
    index, mask = patch_index(nbr)
    aff = head(feats, slots, index, mask)
    assert aff.values.shape == (8, 4) and aff.keep.shape == (8, 2)
    assert (aff.values[~aff.mask] == 0).all() and (aff.values[aff.mask] > 0).all()
    assert (aff.values <= 1).all()
    best = aff.values.masked_fill(~aff.mask, -1).topk(2, dim=1).values
    torch.testing.assert_close(aff.kept, best)


def test_affinity_paper_mode_is_symmetric():
    head = AffinityHead("paper")
    feats = torch.randn(4, 4, 3)
    nbr = torch.tensor([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])
    index, mask = patch_index(nbr)
    v = head(feats, torch.zeros(4, 4, 4, 3), index, mask).values
    dense = torch.zeros(4, 4)
    dense[torch.arange(4)[:, None], nbr] = v
    torch.testing.assert_close(dense, dense.T)
    assert torch.allclose(
        head(feats[:1].expand(4, 4, 3), None, index, mask).values, torch.ones(4, 3), atol=1e-4
    )


def test_affinity_rejects_unknown_mode():
    with pytest.raises(ValueError, match="affinity mode"):
        AffinityHead("cosine")


def test_sparse_affinity_gradient_only_at_kept_and_chain_scaled_by_second_value():
    kept = torch.tensor([[0.9, 0.5], [0.8, 0.3], [0.7, 0.0]], requires_grad=True)
    keep = torch.tensor([[0, 1], [1, 0], [0, 1]])
    nbr = torch.tensor([[1, 2], [0, 2], [1, -1]])
    chain = torch.tensor([[0.0, 0, 1], [0, 0, 0], [1, 0, 0]])
    A = sparse_affinity(kept, keep, nbr, chain=chain)
    expect = torch.tensor([[0.0, 0.9, 0.5 + 0.5], [0.3, 0.0, 0.8], [0.0, 0.7, 0.0]])
    torch.testing.assert_close(A.detach(), expect)
    A[0, 1].backward()
    assert kept.grad[0, 0] == 1 and kept.grad.abs().sum() == 1


# --- PointNet ------------------------------------------------------------------------------------


def test_pointnet_shapes_invariance_and_domains():
    pn = PointNetStream({"toy5": 5, "cmu31": 31}).double()
    x = torch.randn(6, 5, 3, dtype=torch.float64)
    virtual, latent, bary = pn(x)
    assert virtual.shape == (6, 10, 3) and latent.shape == (6, 30) and bary.shape == (6, 1, 3)
    _, latent_p, _ = pn(x[:, torch.randperm(5)])
    torch.testing.assert_close(latent_p, latent)  # order of points does not matter
    assert pn.decode(latent, bary, "toy5").shape == (6, 5, 3)
    with pytest.raises(KeyError, match="no PointNet decoder"):
        pn.decode(latent, bary, "hand21")


# --- network on a synthetic capture --------------------------------------------------------------


@pytest.fixture
def small_view(scene_factory):
    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=0.5, seed=3)
    return sample


@pytest.mark.parametrize("sequencing", ["none", "partial", "full"])
@pytest.mark.parametrize("builder", ["gttnet_tiny", "gttnet_pointnet"])
def test_network_forward(small_view, sequencing, builder):
    torch.manual_seed(0)
    model = build_model(builder, n_joints=5, k=6, domains={"toy5": 5})
    obs, gt = make_view(small_view, sequencing)
    seq = prepare_inputs(obs, k=6)
    assert (seq.chain is not None) == (sequencing != "none")
    outs = model(
        [seq, seq.rotated(torch.as_tensor(random_rotation(np.random.default_rng(0)), dtype=torch.float32))]
    )
    out = outs[0]
    n = obs.n_images
    assert out.a_sparse.shape == (n, n) and out.x_est.shape == (n, 5, 3)
    assert torch.isfinite(out.x_est).all()
    assert (out.a_sparse.diagonal() == 0).all()
    assert (out.pointnet_recon is not None) == (builder == "gttnet_pointnet")
    assert model([seq], solve=False)[0].x_est is None


@pytest.mark.parametrize("mode", ["paper", "reference"])
def test_inference_without_decoder_gives_the_same_affinity_and_structure(small_view, mode):
    # The decoder feeds only the autoencoding loss: skipping it at inference must change nothing else.
    torch.manual_seed(0)
    model = build_model("gttnet_tiny", n_joints=5, k=6, affinity_mode=mode).eval()
    obs, _ = make_view(small_view, "none")
    seq = prepare_inputs(obs, k=6)
    with torch.no_grad():
        full, lean = model([seq])[0], model([seq], decode=False)[0]
    assert full.ae_pairs and not lean.ae_pairs
    torch.testing.assert_close(lean.affinity.values, full.affinity.values, rtol=0, atol=0)
    torch.testing.assert_close(lean.a_sparse, full.a_sparse, rtol=0, atol=0)
    torch.testing.assert_close(lean.x_est, full.x_est, rtol=0, atol=0)


def test_network_rejects_wrong_joint_count(small_view):
    model = build_model("gttnet_tiny", k=6)  # 31 joints
    seq = prepare_inputs(make_view(small_view, "none")[0], k=6)
    with pytest.raises(ValueError, match="PointNet"):
        model([seq])


def test_build_model_rejects_unknown():
    with pytest.raises(ValueError, match="unknown model builder"):
        build_model("gttnet_huge")
    with pytest.raises(ValueError, match="unknown model setting"):
        build_model("gttnet_tiny", depth=3)
    with pytest.raises(ValueError, match="top_q"):
        GTTNetConfig(k=2, top_q=3)


def test_gradcheck_end_to_end_through_affinity_and_solver(scene_factory):
    """Gradient ``d X^E / d X_init`` in float64 on N = 8, J = 3: U-Net → A^D → top-Q A^S → DLOE layer."""
    sample = scene_factory(n_cameras=2, n_joints=3, frames_per_camera=4, sigma_px=1.0, seed=5)
    seq = prepare_inputs(make_view(sample, "none")[0], k=4, dtype=torch.float64)
    torch.manual_seed(0)
    model = build_model("gttnet_tiny", n_joints=3, k=4, widths=(4, 2), hidden=4, prior_weight=None).double()
    x0 = seq.x_init.clone().requires_grad_(True)

    def f(x):
        return model([replace(seq, x_init=x)])[0].x_est

    assert torch.autograd.gradcheck(f, (x0,), eps=1e-6, atol=1e-5, rtol=1e-3)
    x0.grad = None
    f(x0).sum().backward()
    assert x0.grad.abs().sum() > 0  # the affinity really drives X^E


# --- inference -----------------------------------------------------------------------------------


def test_ground_truth_never_reaches_inference(small_view, tmp_path):
    torch.manual_seed(0)
    model = build_model("gttnet_tiny", n_joints=5, k=6)
    path = inference.save_model(tmp_path / "m.pt", model, card={"note": "test"})
    rec = inference.GTTNetReconstructor(path, device="cpu")
    obs, _ = make_view(small_view, "partial")
    ref = rec(obs)
    rng = np.random.default_rng(0)
    corrupt = small_view.replace(
        points3d=rng.normal(size=small_view.points3d.shape),
        affinity_w=rng.random(small_view.affinity_w.shape),
        affinity_nbr=rng.permutation(small_view.affinity_nbr),
    )
    obs_c, gt_c = make_view(corrupt, "partial")
    out = rec(obs_c)
    np.testing.assert_array_equal(out.points3d, ref.points3d)
    np.testing.assert_array_equal(out.affinity, ref.affinity)
    assert not np.allclose(gt_c.points3d, out.points3d, atol=0.5)
    assert (tmp_path / "m.json").is_file()


def test_gttnet_method_in_registry(small_view, tmp_path):
    from gttnet.methods import available_methods, reconstruct

    torch.manual_seed(0)
    path = inference.save_model(tmp_path / "m.pt", build_model("gttnet_tiny", n_joints=5, k=6))
    assert "gttnet" in available_methods()
    obs, _ = make_view(small_view, "none")
    rec = reconstruct(obs, "gttnet", model=str(path))
    assert rec.points3d.shape == (obs.n_images, 5, 3) and rec.order is not None


def test_missing_model_is_a_model_error(tmp_path, monkeypatch):
    monkeypatch.setattr(inference, "BUNDLED_MODEL", tmp_path / "absent.pt")
    with pytest.raises(ModelError, match="no trained model is available"):
        inference.load_model(None)
    with pytest.raises(ModelError, match="no trained model is available"):
        inference.load_model(tmp_path / "nope.pt")
    (tmp_path / "bad.pt").write_bytes(b"not a model")
    with pytest.raises(ModelError, match="model card bad.json"):
        inference.load_model(tmp_path / "bad.pt")


@pytest.fixture()
def tiny_model_path(tmp_path):
    torch.manual_seed(0)
    return str(inference.save_model(tmp_path / "m.pt", build_model("gttnet_tiny", n_joints=5, k=6)))


def test_full_sequencing_returns_timestamp_order_and_uses_the_timing(scene_factory, tiny_model_path):
    """Under full sequencing an untrained network is no worse than DLOE.

    Under full, the order is the timestamp order and the solver interpolates in time, so even an
    untrained network is no worse than DLOE, which is given the same timestamps.
    """
    from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
    from gttnet.methods import reconstruct

    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=10, sigma_px=1.0, seed=7)
    obs, gt = make_view(sample, "full")
    rec = reconstruct(obs, "gttnet", model=tiny_model_path)
    assert kendall_tau(rec.order, gt.global_order) == 1.0
    dloe = reconstruct(obs, "dloe")
    assert mpjpe_mm(rec.points3d, gt.points3d) <= mpjpe_mm(dloe.points3d, gt.points3d)


def test_partial_sequencing_order_never_contradicts_a_stream(scene_factory, tiny_model_path):
    from gttnet.methods import reconstruct

    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=10, sigma_px=1.0, seed=8)
    obs, _ = make_view(sample, "partial")
    rec = reconstruct(obs, "gttnet", model=tiny_model_path)
    for c in np.unique(obs.cam_id):
        members = np.flatnonzero(obs.cam_id == c)
        along = rec.order[members[np.argsort(obs.stream_index[members])]]
        assert (np.diff(along) > 0).all()


def test_order_streams_recovers_each_camera_order_from_poses(scene_factory):
    # Noise-free poses of a smooth motion: every camera's images come out in time order (or reversed),
    # as a partial view over the same images in the same places.
    from gttnet.evaluate.metrics import kendall_tau
    from gttnet.model.inputs import order_streams

    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=12, sigma_px=0.0, seed=5)
    obs, gt = make_view(sample, "none")
    view = order_streams(obs, gt.points3d, k=4)
    assert view.sequencing == "partial" and view.timestamp_s is None
    np.testing.assert_array_equal(view.keypoints_px, obs.keypoints_px)
    for c in np.unique(obs.cam_id):
        mine = np.flatnonzero(obs.cam_id == c)
        assert sorted(view.stream_index[mine].tolist()) == list(range(mine.size))
        assert kendall_tau(view.stream_index[mine], gt.global_order[mine]) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="order-free"):
        order_streams(view, gt.points3d, k=4)
    with pytest.raises(ValueError, match="x_init holds"):
        order_streams(obs, gt.points3d[:-1], k=4)


def test_none_reconstruction_orders_streams_and_keeps_image_order(scene_factory, tiny_model_path):
    # Under none the reconstructor runs the network on the stream-ordered view: the result is the same
    # (to rounding) whatever order the images arrive in, and stream_order=False is the plain path.
    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=10, sigma_px=1.0, seed=9)
    obs, _ = make_view(sample, "none")
    rec = inference.GTTNetReconstructor(tiny_model_path, device="cpu")
    out = rec(obs)
    assert out.info["stream_order"] is True
    perm = np.random.default_rng(1).permutation(obs.n_images)
    out_p = rec(obs.take(perm))
    np.testing.assert_allclose(out_p.points3d, out.points3d[perm], atol=1e-4)
    plain = inference.GTTNetReconstructor(tiny_model_path, device="cpu", stream_order=False)(obs)
    assert plain.info["stream_order"] is False
    assert not np.allclose(plain.points3d, out.points3d, atol=1e-6)
    partial, _ = make_view(sample, "partial")
    assert rec(partial).info["stream_order"] is False


def test_stream_order_default_follows_the_model_family(tmp_path, tiny_model_path, scene_factory):
    # On for the single-topology network; for the PointNet variant on with its DLOE round and off for the
    # network alone (each chosen on its validation captures); an explicit value wins.
    pn = inference.save_model(tmp_path / "pn.pt", build_model("gttnet_pointnet", k=6, domains={"toy5": 5}))
    obs, _ = make_view(scene_factory(n_cameras=3, n_joints=5, frames_per_camera=10, seed=9), "none")

    def ordered(path, stream_order=None, **call):
        rec = inference.GTTNetReconstructor(path, device="cpu", stream_order=stream_order)
        return rec(obs, **call).info["stream_order"]

    assert ordered(tiny_model_path) is True and ordered(tiny_model_path, refine=True) is True
    assert ordered(pn) is True  # refined by default
    assert ordered(pn, refine=False) is False
    assert ordered(pn, stream_order=False) is False and ordered(pn, stream_order=True, refine=False) is True


def test_a_singular_dloe_system_skips_only_that_sequences_structure_loss(small_view, caplog):
    # Training must not end on one degenerate sample: the objective drops its structure loss (logged) and
    # still trains the others; outside training the error is raised as before.
    from gttnet.data import prepare_item
    from gttnet.errors import SingularStructureError
    from gttnet.train.objective import StepObjective
    from gttnet.train.stages import Stage

    torch.manual_seed(0)
    model = build_model("gttnet_tiny", n_joints=5, k=6)
    items = [prepare_item(*make_view(small_view, c), k=6) for c in ("none", "partial")]
    real_solve = model.solve

    def solve(a_sparse, seq, **kw):
        if seq.sequencing == "none":
            raise SingularStructureError("X-step system singular (test)")
        return real_solve(a_sparse, seq, **kw)

    model.solve = solve  # type: ignore[method-assign]
    stage = Stage(name="dloe", losses={"affinity": 1.0, "structure": 100.0}, steps=1)
    total, parts = StepObjective(model)(items, stage)
    assert torch.isfinite(total) and "structure" in parts
    assert "singular" in caplog.text
    total.backward()
    with pytest.raises(SingularStructureError):
        model([items[0].inputs], solve=True)
