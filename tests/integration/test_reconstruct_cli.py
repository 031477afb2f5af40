"""End-to-end ``gttnet reconstruct`` runs on files in every input layout."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gttnet.cli import main
from gttnet.io.output import read_reconstruction
from tests.gttnet.test_importers import write_dloe_mat, write_gttnet_json

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The same small noisy capture (4 cameras, 6 joints, N = 40) as DLOE .mat, GTT-Net JSON and shard."""
    from tests.fixtures.scenes import make_scene

    sample = make_scene(n_cameras=4, n_joints=6, frames_per_camera=10, sigma_px=1.0, seed=4)
    d = tmp_path_factory.mktemp("inputs")
    write_dloe_mat(sample, d / "cap.mat")
    write_gttnet_json(sample, d / "cap.json")
    out = {"mat": d / "cap.mat", "json": d / "cap.json"}
    try:
        from gttdata.shards.writer import ShardWriter

        with ShardWriter(d / "shards", split="test") as w:
            w.write(sample)
        out["h5"] = sorted((d / "shards").glob("*.h5"))[0]
    except ModuleNotFoundError:
        pass
    return out


def _run(*args):
    return CliRunner().invoke(main, ["reconstruct", *map(str, args)])


@pytest.mark.parametrize("layout", ["mat", "json", "h5"])
@pytest.mark.parametrize(
    ("method", "seq"), [("pseudo", "none"), ("dloe", "partial"), ("dct", "full"), ("hpf", "full")]
)
def test_json_summary_and_output(files, tmp_path, layout, method, seq):
    if layout not in files:
        pytest.skip("shard writer not available")
    out = tmp_path / "rec.npz"
    units = [] if layout == "h5" else ["--units", "inch"]  # the test files are in the authors' inches
    res = _run(files[layout], "--method", method, "--sequencing", seq, *units, "--out", out, "--json")
    assert res.exit_code == 0, res.output
    assert "warning" not in res.stderr  # the unit was given, not guessed
    lines = [ln for ln in res.stdout.splitlines() if ln.strip()]
    assert len(lines) == 1
    summary = json.loads(lines[0])
    assert {
        "method",
        "sequencing",
        "n_images",
        "n_joints",
        "seconds",
        "mpjpe_mm",
        "order_kendall_tau",
    } <= set(summary)
    assert summary["method"] == method and summary["sequencing"] == seq
    assert summary["n_images"] == 40 and summary["n_joints"] == 6
    assert 0.0 < summary["mpjpe_mm"] < 80.0
    arrays, attrs = read_reconstruction(out)
    assert arrays["points3d"].shape == (40, 6, 3) and arrays["affinity"].shape == (40, 40)
    assert sorted(arrays["order"].tolist()) == list(range(40))
    assert sorted(arrays["image_index"].tolist()) == list(range(40))
    assert attrs["method"] == method and attrs["units"] == "m"


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (
            ["--method", "dct", "--sequencing", "partial"],
            "method 'dct' needs timestamps (sequencing 'full'); input has sequencing 'partial'",
        ),
        (["--method", "hpf", "--sequencing", "none"], "method 'hpf' needs the global image order"),
        (["--method", "gttnet", "--model", "/nonexistent/model.pt"], "model"),
        (["--method", "pseudo", "--model", "x.pt"], "--model applies only to --method gttnet"),
        (["--format", "h5"], "Error"),
    ],
)
def test_refusals_are_one_line(files, args, expected):
    res = _run(files["mat"], *args)
    assert res.exit_code != 0
    err = [ln for ln in res.output.splitlines() if ln.startswith("Error")]
    assert len(err) == 1 and expected in res.output, res.output
    assert "Traceback" not in res.output


def test_missing_file_and_bad_suffix(tmp_path):
    res = _run(tmp_path / "nope.mat")
    assert res.exit_code != 0 and "nope.mat" in res.output
    bad = tmp_path / "x.txt"
    bad.write_text("hi")
    res = _run(bad)
    assert res.exit_code != 0 and "cannot tell the format" in res.output


def test_mat_without_order_defaults_to_partial(tmp_path, files):
    from tests.fixtures.scenes import make_scene

    sample = make_scene(n_cameras=3, n_joints=5, frames_per_camera=6, seed=2)
    p = tmp_path / "noorder.mat"
    write_dloe_mat(sample, p, caminput_order=0.0)
    res = _run(p, "--method", "pseudo", "--json")
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["sequencing"] == "partial" and "mpjpe_mm" in summary and "order_kendall_tau" not in summary


def test_plain_output_and_h5(tmp_path, files):
    out = tmp_path / "rec.h5"
    res = _run(files["json"], "--method", "pseudo", "--out", out)
    assert res.exit_code == 0, res.output
    assert "method=pseudo" in res.stdout and str(out) in res.stdout
    arrays, attrs = read_reconstruction(out)
    assert attrs["sequencing"] == "full" and np.all(np.isfinite(arrays["points3d"]))


def test_dataset_directory_input(tmp_path):
    """A generated dataset directory (manifest + shards) is read through the dataset reader."""
    from pathlib import Path

    from gttdata.cli import main as gttdata_main

    recipe = Path(__file__).resolve().parents[2] / "recipes" / "gttdata" / "tiny.yaml"
    res = CliRunner().invoke(gttdata_main, ["generate", str(recipe), f"output_dir={tmp_path / 'ds'}"])
    if res.exit_code != 0:
        pytest.skip(f"tiny dataset generation unavailable: {res.output.strip().splitlines()[-1:]}")
    res = _run(tmp_path / "ds", "--sample", 1, "--method", "pseudo", "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["sequencing"] == "full"
    assert "sequencing: full (the richest" in res.stderr  # a defaulted sequencing is said, never silent
    res = _run(tmp_path / "ds", "--sample", 10_000, "--json")
    assert res.exit_code != 0 and "split 'test' holds samples 0-1, got --sample 10000" in res.output
    train = _run(tmp_path / "ds", "--split", "train", "--sample", 3, "--method", "pseudo", "--json")
    assert train.exit_code == 0, train.output  # the tiny train split has 4 samples, test only 2
    bad = _run(tmp_path / "ds", "--split", "nope", "--json")
    assert bad.exit_code == 1 and "nope" in bad.output and "Traceback" not in bad.output
