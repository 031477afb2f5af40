"""``--method gttnet`` picks the bundled model by topology: CMU-31 model for CMU-31, PointNet otherwise."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.capture.views import make_view
from gttdata.skeleton import cmu31
from gttdata.skeletons import get_skeleton
from gttnet.errors import ModelError
from gttnet.model import inference
from gttnet.model.network import gttnet_pointnet
from tests.gttnet.test_authors_json import _sample


@pytest.fixture(scope="module")
def coco_sample():
    return _sample("coco17")


@pytest.fixture
def pointnet_bundle(tmp_path, monkeypatch):
    """An (untrained) PointNet model installed as the bundled cross-domain model."""
    path = inference.save_model(tmp_path / "gttnet_pointnet.pt", gttnet_pointnet(k=8, domains={"hand21": 21}))
    monkeypatch.setattr(inference, "BUNDLED_POINTNET_MODEL", path)
    inference.cached_reconstructor.cache_clear()  # models loaded by other tests are not this one
    yield path
    inference.cached_reconstructor.cache_clear()


def test_bundled_choice_by_topology(pointnet_bundle):
    assert inference.bundled_model_for(cmu31()) == inference.BUNDLED_MODEL
    for name in ("coco17", "hand21", "quadruped36"):
        assert inference.bundled_model_for(get_skeleton(name)) == pointnet_bundle


def test_missing_pointnet_model_says_how_to_get_one(tmp_path, monkeypatch, coco_sample):
    monkeypatch.setattr(inference, "BUNDLED_POINTNET_MODEL", tmp_path / "absent.pt")
    with pytest.raises(ModelError, match=r"coco17.*17 joints.*pointnet\.yaml.*--model"):
        inference.reconstruct_gttnet(make_view(coco_sample, "none", seed=0)[0])


def test_gttnet_on_a_17_joint_input_uses_the_pointnet_model(pointnet_bundle, coco_sample):
    obs, _ = make_view(coco_sample, "none", seed=0)
    rec = inference.reconstruct_gttnet(obs)
    assert rec.points3d.shape == (coco_sample.n_images, 17, 3)


def test_cli_gttnet_on_authors_17_joint_file(tmp_path, pointnet_bundle, coco_sample):
    from gttnet.cli import main
    from gttnet.io.gttnet_json import write_gttnet_json

    path = write_gttnet_json(coco_sample, tmp_path / "authors_layout.json")
    args = ["reconstruct", str(path), "--method", "gttnet", "--sequencing", "none", "--json"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    out = json.loads(res.output.strip().splitlines()[-1])
    assert out["method"] == "gttnet" and out["n_joints"] == 17 and "mpjpe_mm" in out
    # --model overrides the choice: the CMU-31 model refuses 17 joints with one line.
    res = CliRunner().invoke(main, [*args, "--model", str(inference.BUNDLED_MODEL)])
    assert res.exit_code != 0 and "31 joints" in res.output and "Traceback" not in res.output


def test_pointnet_polishes_with_dloe_by_default_without_sequencing(pointnet_bundle, coco_sample):
    from gttnet.baselines.dloe import reconstruct_dloe

    obs, _ = make_view(coco_sample, "none", seed=0)
    assert inference.REFINE_DEFAULT[(True, "none")] and not inference.REFINE_DEFAULT.get((False, "none"))
    assert not inference.REFINE_DEFAULT.get((False, "full"))
    # The network's structure as the default path computes it (streams ordered first, as with the round).
    raw = inference.reconstruct_gttnet(obs, refine=False, stream_order=True)
    rec = inference.reconstruct_gttnet(obs)
    assert rec.info["refined"] and not raw.info["refined"] and rec.info["stream_order"]
    assert rec.info["refine_iterations"] == inference.REFINE_ROUNDS
    # The refinement is DLOE's alternation started at the network's structure, nothing more.
    polished = reconstruct_dloe(
        obs, candidates="auto", x_start=raw.points3d, max_iter=inference.REFINE_ROUNDS
    )
    np.testing.assert_array_equal(rec.points3d, polished.points3d)
    # ... and the recovered order is that of the refined poses.
    from gttnet.model.inputs import pose_order

    np.testing.assert_array_equal(rec.order, pose_order(rec.points3d, k=16))
    assert not np.array_equal(rec.points3d, raw.points3d)


def test_cli_refine_switch(tmp_path, pointnet_bundle, coco_sample):
    from gttnet.cli import main
    from gttnet.io.gttnet_json import write_gttnet_json

    path = write_gttnet_json(coco_sample, tmp_path / "cap.json")
    base = ["reconstruct", str(path), "--sequencing", "none", "--json", "--seed", "0"]
    out = {}
    for flag in ("--refine", "--no-refine"):
        res = CliRunner().invoke(main, [*base, "--method", "gttnet", flag])
        assert res.exit_code == 0, res.output
        out[flag] = json.loads(res.output.strip().splitlines()[-1])
    assert out["--refine"]["refined"] is True and out["--no-refine"]["refined"] is False
    assert out["--refine"]["mpjpe_mm"] != out["--no-refine"]["mpjpe_mm"]
    res = CliRunner().invoke(main, [*base, "--method", "dloe", "--no-refine"])
    assert res.exit_code != 0 and "apply only to --method gttnet" in res.output


@pytest.mark.parametrize("installed", [True, False])
def test_cmu31_without_sequencing_uses_the_order_free_model_when_installed(installed, tmp_path, monkeypatch):
    none_model = tmp_path / "gttnet_default_none.pt"
    if installed:
        none_model.write_bytes(b"x")  # only its presence is read here
    monkeypatch.setattr(inference, "BUNDLED_NONE_MODEL", none_model)
    expected = none_model if installed else inference.BUNDLED_MODEL
    assert inference.bundled_model_for(cmu31(), "none") == expected
    for sequencing in ("partial", "full", None):
        assert inference.bundled_model_for(cmu31(), sequencing) == inference.BUNDLED_MODEL


def test_shipped_order_free_model_verifies_and_fits_cmu31():
    card = json.loads(inference.BUNDLED_NONE_MODEL.with_suffix(".json").read_text())
    model = inference.load_model(inference.BUNDLED_NONE_MODEL)  # checks the card's sha256
    assert model.config.n_joints == card["config"]["n_joints"] == 31
    assert card["recipe"]["data"]["sequencing"] == {"none": 1.0}
    assert card["recipe"]["data"]["stream_order"] is True  # trained on the inputs inference gives it


def test_shipped_pointnet_model_reads_an_authors_17_joint_file_without_model(tmp_path):
    # The bar's command, with the model as shipped (no fixture): H36M-17 is a topology it never saw.
    from gttnet.cli import main
    from gttnet.io.gttnet_json import write_gttnet_json

    inference.cached_reconstructor.cache_clear()
    assert inference.bundled_model_for(get_skeleton("h36m17")) == inference.BUNDLED_POINTNET_MODEL
    path = write_gttnet_json(_sample("h36m17"), tmp_path / "authors_layout.json")
    args = ["reconstruct", str(path), "--method", "gttnet", "--sequencing", "none", "--json"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    out = json.loads(res.output.strip().splitlines()[-1])
    # Runs and scores only: 24 images at 10 Hz is no accuracy test (docs/MODEL_CARD_POINTNET.md has those).
    assert out["method"] == "gttnet" and out["n_joints"] == 17 and math.isfinite(out["mpjpe_mm"])
