"""The authors' GTT-Net JSON layout.

The authors' GTT-Net JSON layout (scalar K = 0 with rays, camID, t, limbSeq, X_init, rayDInd): read,
write, round trip, and one-line errors.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.capture.views import make_view
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe, parse_recipe, recipe_to_dict
from gttnet.errors import ImportFormatError
from gttnet.io import load_input
from gttnet.io.gttnet_json import read_gttnet_json, skeleton_from_limbs, write_gttnet_json


def _sample(skeleton: str = "coco17"):
    data = recipe_to_dict(load_recipe("recipes/gttdata/tiny.yaml"))
    data["splits"][0]["sources"][0]["skeleton"] = skeleton
    data["augmentations"] = []
    return build_sample(parse_recipe(data), "train", 0)[0]


@pytest.fixture(scope="module")
def coco_sample():
    return _sample("coco17")


@pytest.mark.parametrize("units", ["inch", "m"])
def test_round_trip_authors_layout(tmp_path, coco_sample, units):
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json", units=units)
    d = json.loads(path.read_text())
    assert d["K"] == 0 and np.asarray(d["ray"]).shape == (3 * 17, coco_sample.n_images)
    assert {"camID", "t", "C", "point3D", "limbSeq", "X_init", "rayDInd"} <= set(d)
    cap = read_gttnet_json(path, units=units)
    assert cap.skeleton.name == "coco17"  # the limb list identifies the registered topology
    obs, gt = make_view(coco_sample, "full")
    loaded = load_input(path, sequencing="full", units=units)
    np.testing.assert_allclose(loaded.observations.rays(), obs.rays(), atol=1e-9)
    np.testing.assert_allclose(loaded.observations.centers(), obs.centers(), atol=1e-9)
    np.testing.assert_array_equal(loaded.observations.visible, obs.visible)
    np.testing.assert_array_equal(loaded.observations.cam_id, obs.cam_id)
    np.testing.assert_allclose(loaded.ground_truth.points3d, gt.points3d, atol=1e-9)
    np.testing.assert_array_equal(loaded.ground_truth.global_order, np.arange(coco_sample.n_images))
    with pytest.raises(FileExistsError, match="overwrite"):
        write_gttnet_json(coco_sample, path)


def test_authors_file_with_cycling_camids_and_unsorted_times(tmp_path, coco_sample):
    """``camID`` given once per camera and cycling; t out of file order; 0-based limbSeq: order from t."""
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json")
    d = json.loads(path.read_text())
    n = len(d["camID"])
    V = coco_sample.n_cameras
    # Rebuild a file whose images cycle over cameras 0..V-1 (drop the tail that breaks the cycle).
    cams = np.asarray(d["camID"]) - 1
    keep, want = [], 0
    for i in range(n):
        if cams[i] == want:
            keep.append(i)
            want = (want + 1) % V
    keep = keep[: len(keep) // V * V]
    rev = keep[::-1]  # store them in reverse time order: t must restore the order
    cols = lambda a: np.asarray(a)[:, rev].tolist()  # noqa: E731
    authors = {
        "camID": list(range(V, 0, -1)),  # reversed storage: cameras V..1, then again
        "t": np.asarray(d["t"])[rev].tolist(),
        "K": 0,
        "C": cols(d["C"]),
        "ray": cols(d["ray"]),
        "point3D": cols(d["point3D"]),
        "limbSeq": (np.asarray(d["limbSeq"]) - 1).tolist(),
        "X_init": cols(d["X_init"]),
        "rayDInd": [[0]],
    }
    p2 = tmp_path / "authors.json"
    p2.write_text(json.dumps(authors))
    cap = read_gttnet_json(p2)
    assert cap.n_images == len(keep) and cap.skeleton.name == "coco17"
    np.testing.assert_array_equal(cap.time_rank, np.arange(len(keep))[::-1])
    loaded = load_input(p2, sequencing="full")
    obs, _ = make_view(coco_sample, "full")
    np.testing.assert_allclose(loaded.observations.rays(), obs.rays()[keep], atol=1e-9)
    np.testing.assert_array_equal(loaded.observations.cam_id, obs.cam_id[keep])


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        ({"K": 5}, r"field 'K': expected a \(3, 3V\) array or the scalar 0"),
        ({"limbSeq": [[1, 99]]}, r"field 'limbSeq': expected joint indices"),
        ({"limbSeq": [[1, 2, 3]]}, r"field 'limbSeq': expected shape"),
        ({"t": [0.0, 1.0]}, r"field 't': expected N = "),
        ({"camID": [1, 2, 3, 4, 5, 6, 7]}, r"field 'camID': expected N = "),
        ({"ray": [[0.0]]}, r"field 'ray': expected shape \(3P, N\)"),
    ],
)
def test_authors_layout_malformed_names_field(tmp_path, coco_sample, edit, match):
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json")
    d = json.loads(path.read_text())
    d.update(edit)
    path.write_text(json.dumps(d))
    with pytest.raises(ImportFormatError, match=match) as exc:
        read_gttnet_json(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_skeleton_from_unknown_limbs_is_a_forest_with_extra_bones():
    sk = skeleton_from_limbs(np.array([[0, 1], [1, 2], [2, 0], [3, 4]]), 6)
    assert sk.parents == (-1, 0, 0, -1, 3, -1) and sk.extra_bones == ((1, 2),)


def test_cli_reconstructs_a_17_joint_authors_file(tmp_path, coco_sample):
    from gttnet.cli import main

    path = write_gttnet_json(coco_sample, tmp_path / "authors_layout.json")
    res = CliRunner().invoke(
        main, ["reconstruct", str(path), "--method", "pseudo", "--sequencing", "none", "--json"]
    )
    assert res.exit_code == 0, res.output
    out = json.loads(res.output.strip().splitlines()[-1])
    assert out["n_joints"] == 17 and out["sequencing"] == "none"


def test_cli_export_json_then_reconstruct(tmp_path):
    from gttnet.cli import main

    out = tmp_path / "authors_layout.json"
    args = [
        "export-json",
        "recipes/gttdata/tiny_topologies.yaml",
        "--split",
        "test",
        "--out",
        str(out),
        "--json",
    ]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    info = json.loads(res.output.strip().splitlines()[-1])
    written = json.loads(out.read_text())
    assert info["n_joints"] == len(written["ray"]) // 3
    assert info["units"] == written["units"] == "m"  # metres unless --units says otherwise, and recorded
    again = CliRunner().invoke(main, args)
    assert again.exit_code != 0 and "--overwrite" in again.output and "Traceback" not in again.output
    res = CliRunner().invoke(
        main, ["reconstruct", str(out), "--method", "pseudo", "--sequencing", "none", "--json"]
    )
    assert res.exit_code == 0, res.output
    assert "warning" not in res.stderr  # the file records its unit: nothing is guessed
    assert json.loads(res.stdout.strip().splitlines()[-1])["n_joints"] == info["n_joints"]
