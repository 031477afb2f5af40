"""The method registry and the pseudo / DCT / HPF baselines, and that ground truth never reaches a solver."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttnet.baselines.highpass import difference_operator, fit_highpass
from gttnet.baselines.trajectory_basis import dct_basis, fit_trajectory_basis
from gttnet.errors import GttNetError, ModelError, SequencingError
from gttnet.evaluate.metrics import mpjpe_mm
from gttnet.io import load_input
from gttnet.methods import Reconstruction, available_methods, reconstruct, register_method
from tests.gttnet.test_importers import write_dloe_mat, write_gttnet_json

BUILTIN = {"pseudo": "none", "dloe": "none", "dct": "full", "hpf": "full"}


@pytest.fixture(scope="module")
def scene():
    """4 cameras, 8 joints, 20 frames each (N = 80), 1 px noise, 10 % missing joints."""
    from tests.fixtures.scenes import make_scene

    return make_scene(n_cameras=4, n_joints=8, frames_per_camera=20, sigma_px=1.0, missing=0.1, seed=7)


def test_available_methods():
    methods = available_methods()
    for name, needs in {**BUILTIN, "gttnet": "none"}.items():
        assert methods[name] == needs


def test_builtin_method_table_names_each_module_that_registers():
    """``BUILTIN_METHODS`` (lookup imports one module) lists exactly the built-ins, each with its module."""
    import subprocess
    import sys

    from tests._subprocess import repo_env

    code = (
        "import json\nfrom gttnet.methods import BUILTIN_METHODS, available_methods, method_spec\n"
        "available_methods()\n"
        "print(json.dumps({n: method_spec(n).fn.__module__ for n in available_methods()}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=repo_env(), check=True
    )
    import json

    from gttnet.methods import BUILTIN_METHODS

    assert json.loads(out.stdout.strip().splitlines()[-1]) == BUILTIN_METHODS


@pytest.mark.parametrize(("method", "seq"), [("dct", "partial"), ("dct", "none"), ("hpf", "partial")])
def test_sequencing_refused(scene, method, seq):
    obs, _ = make_view(scene, seq)
    with pytest.raises(
        SequencingError, match=f"method '{method}' needs .*sequencing 'full'.*input has sequencing '{seq}'"
    ):
        reconstruct(obs, method)


def test_dct_message_names_timestamps(scene):
    obs, _ = make_view(scene, "partial")
    with pytest.raises(SequencingError) as exc:
        reconstruct(obs, "dct")
    assert (
        str(exc.value) == "method 'dct' needs timestamps (sequencing 'full'); input has sequencing 'partial'"
    )


def test_unknown_method_and_option(scene):
    obs, _ = make_view(scene, "none")
    with pytest.raises(ValueError, match="unknown method 'nope'"):
        reconstruct(obs, "nope")
    with pytest.raises(ValueError, match="has no option 'bogus'"):
        reconstruct(obs, "pseudo", bogus=1)


def test_gttnet_without_model(scene):
    obs, _ = make_view(scene, "none")
    with pytest.raises(ModelError, match="no trained model"):
        reconstruct(obs, "gttnet", model="/nonexistent/model.pt")


def test_register_custom_method(scene, monkeypatch):
    from click.testing import CliRunner

    import gttnet.methods
    from gttnet.cli import main

    available_methods()  # built-ins loaded, then a private copy of the registry for this test
    monkeypatch.setattr(gttnet.methods, "_REGISTRY", dict(gttnet.methods._REGISTRY))

    @register_method("_test_zero", requires="partial")
    def _zero(obs):
        n = obs.n_images
        return Reconstruction(points3d=np.zeros((n, obs.n_joints, 3)), affinity=np.eye(n, k=1))

    obs, _ = make_view(scene, "partial")
    rec = reconstruct(obs, "_test_zero")
    assert rec.method == "_test_zero" and rec.sequencing == "partial" and rec.seconds >= 0
    np.testing.assert_array_equal(rec.order, np.arange(obs.n_images))  # filled from the affinity
    with pytest.raises(SequencingError):
        reconstruct(make_view(scene, "none")[0], "_test_zero")
    assert "_test_zero" in CliRunner().invoke(main, ["reconstruct", "--help"]).output  # the CLI lists it


@pytest.mark.parametrize("method", ["pseudo", "dloe", "dct", "hpf"])
def test_every_method_shapes_and_accuracy(scene, method):
    obs, gt = make_view(scene, "full")
    rec = reconstruct(obs, method)
    n, j = obs.n_images, obs.n_joints
    assert rec.points3d.shape == (n, j, 3) and np.all(np.isfinite(rec.points3d))
    assert rec.affinity.shape == (n, n) and rec.order.shape == (n,)
    assert sorted(rec.order.tolist()) == list(range(n))
    assert mpjpe_mm(rec.points3d, gt.points3d) < 60.0


def test_dct_exact_on_basis_trajectories():
    """Noise-free rays of trajectories inside the DCT span are fitted to numerical precision."""
    rng = np.random.default_rng(0)
    n, J, k = 40, 3, 5
    t = np.sort(rng.uniform(0, 2, n))
    beta = rng.normal(size=(J, k, 3)) * 0.2
    X = np.einsum("nk,jka->nja", dct_basis(t, k), beta)
    ang = rng.uniform(0, 2 * np.pi, n)
    C = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.ones(n)], -1)
    r = X - C[:, None]
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    Xf = fit_trajectory_basis(t, C, r, np.ones((n, J), bool), k=k)
    np.testing.assert_allclose(Xf, X, atol=1e-7)


def test_hpf_exact_on_linear_motion():
    """Linear motion has zero second difference, so any weight recovers it exactly from exact rays."""
    rng = np.random.default_rng(1)
    n, J = 30, 2
    X = rng.normal(size=(1, J, 3)) * 0.3 + np.linspace(0, 1, n)[:, None, None] * rng.normal(size=(1, J, 3))
    ang = rng.uniform(0, 2 * np.pi, n)
    C = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.ones(n)], -1)
    r = X - C[:, None]
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    vis = np.ones((n, J), bool)
    vis[5, 0] = False  # a missing joint is interpolated by the prior
    np.testing.assert_allclose(fit_highpass(C, r, vis, lam=10.0), X, atol=1e-7)
    assert difference_operator(5, 1).toarray().tolist()[0] == [-1, 1, 0, 0, 0]


def test_hpf_bracket_search_scores_a_subset_of_the_grid(scene):
    """The coarse-to-fine search scores 9 of the 13 weights exactly as the full grid does, around its best."""
    from gttnet.baselines.highpass import LAMBDAS

    obs, _ = make_view(scene, "full")
    grid = reconstruct(obs, "hpf", n_folds=3).info["cv_ray_error_m"]
    bracket = reconstruct(obs, "hpf", n_folds=3, search="bracket").info["cv_ray_error_m"]
    assert len(grid) == len(LAMBDAS) and len(bracket) == 9
    assert all(grid[k] == v for k, v in bracket.items())
    best = min(grid, key=grid.__getitem__)
    assert best in bracket  # the score is unimodal in log(lam) here: the bracket finds the grid's best
    with pytest.raises(ValueError, match="search must be 'grid' or 'bracket'"):
        reconstruct(obs, "hpf", search="golden")


@pytest.mark.parametrize("start", ["best", "lowest", "highest"])
def test_hpf_search_from_a_start_walks_to_the_grids_best(scene, start):
    """``lam_start`` (a neighbouring window's weight) scores 3 weights when right, and walks when wrong."""
    from gttnet.baselines.highpass import LAMBDAS

    obs, _ = make_view(scene, "full")
    full = reconstruct(obs, "hpf", n_folds=3)
    grid = full.info["cv_ray_error_m"]
    best = min(grid, key=grid.__getitem__)
    lam0 = {"best": float(best), "lowest": LAMBDAS[0], "highest": LAMBDAS[-1]}[start]
    rec = reconstruct(obs, "hpf", n_folds=3, lam_start=lam0 * 1.1)  # off the grid: the nearest weight
    local = rec.info["cv_ray_error_m"]
    assert all(grid[k] == v for k, v in local.items())  # the same scores as the full grid
    assert rec.info["lam"] == full.info["lam"]
    np.testing.assert_array_equal(rec.points3d, full.points3d)
    if start == "best" and best not in (f"{LAMBDAS[0]:g}", f"{LAMBDAS[-1]:g}"):
        assert len(local) == 3


def test_hpf_pinned_joints_match_the_einsum_definition():
    """The matrix-product form of the pinned check gives the three-operand einsum's normal matrices."""
    from gttnet.baselines._rays import ray_projectors
    from gttnet.baselines.highpass import _pinned_by_rays

    rng = np.random.default_rng(3)
    n, J = 40, 5
    rays = rng.normal(size=(n, J, 3))
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    vis = rng.random((n, J)) > 0.3
    vis[:, 1] = False
    vis[7, 1] = True  # one ray: the prior's null space is free
    vis[:, 2] = False
    vis[[3, 30], 2] = True  # two rays at two times: an order-2 prior's straight lines are pinned down
    P = ray_projectors(rays, vis)
    s = np.sort(rng.random(n))
    for order in (1, 2, 3):
        B = ((s - s.min()) / np.ptp(s))[:, None] ** np.arange(order)[None, :]
        N = np.einsum("na,nb,njcd->jacbd", B, B, P).reshape(J, 3 * order, 3 * order)
        ev = np.linalg.eigvalsh(N)
        want = ev[:, 0] > 1e-9 * np.maximum(ev[:, -1], 1e-300)
        got = _pinned_by_rays(P, order, s)
        np.testing.assert_array_equal(got, want)
        assert not got[1]


def test_trajectory_methods_beat_pseudo(scene):
    obs, gt = make_view(scene, "full")
    base = mpjpe_mm(reconstruct(obs, "pseudo").points3d, gt.points3d)
    for m in ("dct", "hpf"):
        assert mpjpe_mm(reconstruct(obs, m).points3d, gt.points3d) < 0.8 * base


def _corrupt(gt):
    rng = np.random.default_rng(123)
    return dataclasses.replace(
        gt,
        points3d=rng.normal(size=gt.points3d.shape),
        timestamp_s=rng.permutation(gt.timestamp_s),
        global_order=rng.permutation(gt.global_order),
        affinity_nbr=rng.permutation(gt.affinity_nbr),
        affinity_w=rng.random(gt.affinity_w.shape),
    )


@pytest.mark.parametrize("method", ["pseudo", "dloe", "dct", "hpf"])
def test_ground_truth_never_reaches_a_solver(scene, method):
    """Corrupting the ground truth (in memory, and the GT stored in the sample) changes no output bit."""
    obs, gt = make_view(scene, "full")
    bad_sample = dataclasses.replace(
        scene,
        points3d=np.random.default_rng(5).normal(size=scene.points3d.shape),
        keypoints_gt_px=np.zeros_like(scene.keypoints_gt_px),
        affinity_w=np.zeros_like(scene.affinity_w),
    )
    obs_bad, gt_bad = make_view(bad_sample, "full")
    _ = _corrupt(gt)  # corrupted GroundTruth objects exist alongside; reconstruct() cannot take them
    a = reconstruct(obs, method)
    b = reconstruct(obs_bad, method)
    assert not np.array_equal(gt.points3d, gt_bad.points3d)
    np.testing.assert_array_equal(a.points3d, b.points3d)
    np.testing.assert_array_equal(a.affinity, b.affinity)
    np.testing.assert_array_equal(a.order, b.order)


def _write_shard(sample, out_dir):
    writer = pytest.importorskip("gttdata.shards.writer")
    with writer.ShardWriter(out_dir, split="test") as w:
        w.write(sample)
    return sorted(out_dir.glob("*.h5"))[0]


@pytest.mark.parametrize("layout", ["mat", "json", "h5"])
def test_ground_truth_in_files_never_reaches_a_solver(tmp_path, scene, layout):
    """Replacing the ground-truth arrays stored in an input file leaves every method's output bit-identical."""
    good, bad = tmp_path / f"good.{layout}", tmp_path / f"bad.{layout}"
    rng = np.random.default_rng(9)
    p, n = scene.n_joints, scene.n_images
    if layout == "h5":
        good = _write_shard(scene, tmp_path / "good")
        bad_sample = dataclasses.replace(
            scene,
            points3d=rng.normal(size=scene.points3d.shape),
            keypoints_gt_px=rng.normal(size=scene.keypoints_gt_px.shape).astype(np.float32),
            affinity_w=rng.random(scene.affinity_w.shape),
        )
        bad = _write_shard(bad_sample, tmp_path / "bad")
    elif layout == "mat":
        write_dloe_mat(scene, good)
        write_dloe_mat(scene, bad, X_GT=rng.normal(size=(3 * p, n)))
    else:
        write_gttnet_json(scene, good)
        write_gttnet_json(scene, bad, point3D=rng.normal(size=(3 * p, n)).tolist())
    for method in BUILTIN:
        a_in, b_in = load_input(good, sequencing="full"), load_input(bad, sequencing="full")
        assert not np.allclose(a_in.ground_truth.points3d, b_in.ground_truth.points3d)
        a, b = reconstruct(a_in.observations, method), reconstruct(b_in.observations, method)
        np.testing.assert_array_equal(a.points3d, b.points3d)
        np.testing.assert_array_equal(a.order, b.order)


def _hide(obs, joint, keep_images=()):
    """``obs`` with ``joint`` missing everywhere except in the images ``keep_images``."""
    vis = obs.visible.copy()
    vis[:, joint] = False
    vis[list(keep_images), joint] = obs.visible[list(keep_images), joint]
    return dataclasses.replace(obs, visible=vis)


@pytest.mark.parametrize(
    ("method", "seq"), [("pseudo", "none"), ("dloe", "none"), ("hpf", "full"), ("dct", "full")]
)
def test_joint_missing_everywhere_is_nan_and_named(scene, method, seq, caplog):
    obs, gt = make_view(scene, seq)
    blank = _hide(obs, 3)
    with caplog.at_level("WARNING", logger="gttnet.methods"):
        rec = reconstruct(blank, method)
    assert np.isnan(rec.points3d[:, 3]).all()
    others = np.delete(np.arange(obs.n_joints), 3)
    assert np.isfinite(rec.points3d[:, others]).all()
    assert rec.info["unobserved_joints"] == [obs.skeleton.joint_names[3]]
    assert f"joint {obs.skeleton.joint_names[3]} missing in every image" in caplog.text
    # the other joints are still reconstructed about as well as with the joint present
    full = reconstruct(obs, method)
    assert (
        mpjpe_mm(rec.points3d[:, others], gt.points3d[:, others])
        < 1.5 * mpjpe_mm(full.points3d[:, others], gt.points3d[:, others]) + 1.0
    )


def test_no_joint_observed_is_one_clear_error(scene):
    obs, _ = make_view(scene, "none")
    with pytest.raises(
        GttNetError, match="no joint of the 8-joint skeleton .* is observed in any of the 80 images"
    ):
        reconstruct(dataclasses.replace(obs, visible=np.zeros_like(obs.visible)), "pseudo")


@pytest.mark.parametrize(
    ("method", "options", "logger"),
    [
        ("hpf", {"lam": 10.0}, "gttnet.baselines._rays"),
        ("dct", {"k": 6}, "gttnet.baselines._rays"),
    ],
)
@pytest.mark.parametrize("n_seen", [1, 2])
def test_a_trajectory_prior_leaves_an_undetermined_joint_nan(scene, caplog, method, options, logger, n_seen):
    """One or two rays cannot fix a straight-line trajectory: that joint is NaN, the rest are solved."""
    obs, gt = make_view(scene, "full")
    seen = np.flatnonzero(obs.visible[:, 2])[:: max(1, obs.n_images // 3)][:n_seen]
    with caplog.at_level("WARNING", logger=logger):
        rec = reconstruct(_hide(obs, 2, keep_images=seen), method, **options)
    assert np.isnan(rec.points3d[:, 2]).all()
    assert np.isfinite(np.delete(rec.points3d, 2, axis=1)).all()
    assert rec.info["undetermined_joints"] == [obs.skeleton.joint_names[2]]
    assert f"({n_seen} observations): left NaN" in caplog.text
    # the joint with all its rays is solved as before
    assert np.allclose(rec.points3d[:, 0], reconstruct(obs, method, **options).points3d[:, 0])


def _write_hidden(scene, visible, path):
    """``scene`` as a GTT-Net JSON file with only ``visible`` observed (the others' pixels NaN)."""
    px = np.where(visible[..., None], scene.keypoints_px, np.nan)
    write_gttnet_json(dataclasses.replace(scene, visible=visible, keypoints_px=px), path)
    return path


def test_cli_reports_a_never_seen_joint_and_writes_gaps(tmp_path, scene):
    """The CLI keeps a valid JSON summary (MPJPE over the reconstructed joints) and writes the gap out."""
    from click.testing import CliRunner

    from gttnet.cli import main
    from gttnet.io.motion_files import read_trc

    vis = scene.visible.copy()
    vis[:, 3] = False
    path = _write_hidden(scene, vis, tmp_path / "cap.json")
    trc = tmp_path / "out.trc"
    res = CliRunner().invoke(
        main,
        [
            "reconstruct",
            str(path),
            "--units",
            "m",
            "--method",
            "dloe",
            "--sequencing",
            "none",
            "--json",
            "--out",
            str(trc),
        ],
    )
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output.strip().splitlines()[-1])
    assert summary["nan_joints"] == [3] and np.isfinite(summary["mpjpe_mm"])
    _, _, points, _ = read_trc(trc)
    assert np.isnan(points[:, 3]).all() and np.isfinite(np.delete(points, 3, axis=1)).all()


@pytest.mark.parametrize("sequencing", ["none", "partial"])
def test_cli_warns_about_images_that_see_no_joint(tmp_path, scene, sequencing):
    """Without sequencing an image with no detection cannot be placed: the CLI says so and counts them."""
    from click.testing import CliRunner

    from gttnet.cli import main

    vis = scene.visible.copy()
    vis[:5] = False
    path = _write_hidden(scene, vis, tmp_path / "cap.json")
    args = [
        "reconstruct",
        str(path),
        "--units",
        "m",
        "--method",
        "dloe",
        "--sequencing",
        sequencing,
        "--json",
    ]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output.strip().splitlines()[-1])
    assert summary["images_without_joints"] == 5
    warned = f"warning: 5 of {scene.n_images} images see no joint" in res.output
    assert warned == (sequencing == "none")
