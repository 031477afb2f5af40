"""The authors' GTT-Net JSON layout.

The authors' GTT-Net JSON layout (scalar K = 0 with rays, camID, t, limbSeq, X_init, rayDInd): read,
write, round trip, and one-line errors.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gttdata.capture.views import make_view
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe, parse_recipe, recipe_to_dict
from gttnet.errors import ImportFormatError
from gttnet.io import load_input
from gttnet.io.gttnet_json import adjacency_lists, read_gttnet_json, skeleton_from_limbs, write_gttnet_json


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
        "limbSeq": [[j - 1 for j in row] for row in d["limbSeq"]],  # 0-based adjacency lists
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
        ({"limbSeq": [["a", 2]]}, r"field 'limbSeq': row 0: expected a list of joint indices"),
        ({"limbSeq": [[1, 2.5]]}, r"field 'limbSeq': expected integer joint indices, found 2.5"),
        ({"limbSeq": []}, r"field 'limbSeq': expected joint index pairs or adjacency lists"),
        ({"limbSeq": "1-2"}, r"field 'limbSeq': expected joint index pairs or adjacency lists"),
        ({"limbSeq": [[1], [2]]}, r"field 'limbSeq': expected at least one limb"),
        ({"limbSeq": [[1, [2, 3]]]}, r"field 'limbSeq': row 0: expected a list of joint indices"),
        ({"C": [[0.0]]}, r"field 'C': expected shape \(3, N\)"),
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


def _edges(sk) -> set:
    return {frozenset(map(int, e)) for e in sk.limbs}


@pytest.mark.parametrize(
    "form",
    [
        "adjacency",
        "adjacency-wrapped",
        "adjacency-rows-wrapped",
        "adjacency-bare-numbers",
        "pairs",
        "pairs-2xL",
    ],
)
def test_limbseq_in_every_published_form_gives_the_same_skeleton(tmp_path, coco_sample, form):
    """The authors' adjacency lists, their MATLAB-wrapped forms and index pairs all name COCO-17's limbs."""
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json", limb_format="pairs")
    d = json.loads(path.read_text())
    pairs = d["limbSeq"]
    adjacency = adjacency_lists(np.asarray(pairs))
    d["limbSeq"] = {
        "adjacency": adjacency,
        "adjacency-wrapped": [adjacency],
        "adjacency-rows-wrapped": [[row] for row in adjacency],
        # MATLAB writes a one-element row as a bare number: a joint listed without neighbours.
        "adjacency-bare-numbers": [*adjacency, 17],
        "pairs": pairs,
        "pairs-2xL": np.asarray(pairs).T.tolist(),
    }[form]
    path.write_text(json.dumps(d))
    cap = read_gttnet_json(path)
    assert cap.skeleton.name == "coco17"
    assert _edges(cap.skeleton) == _edges(coco_sample.skeleton)


def test_adjacency_rows_of_three_are_not_mistaken_for_pairs(tmp_path, coco_sample):
    """``[[1, 2, 3]]`` is joint 1 with neighbours 2 and 3 (it used to be refused as a malformed table)."""
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json")
    d = json.loads(path.read_text())
    d["limbSeq"] = [[1, 2, 3], [3, 4, 5], [5, 6, 7]]  # 1-based, 7 of the 17 joints
    d["limbSeq"].append([17, 16])  # the largest index is P: 1-based
    path.write_text(json.dumps(d))
    sk = read_gttnet_json(path).skeleton
    assert _edges(sk) == {frozenset(e) for e in [(0, 1), (0, 2), (2, 3), (2, 4), (4, 5), (4, 6), (16, 15)]}


def test_export_json_writes_the_authors_adjacency_lists(tmp_path, coco_sample):
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json")
    rows = json.loads(path.read_text())["limbSeq"]
    assert any(len(r) != 2 for r in rows)  # adjacency rows, not pairs (COCO-17 has joints with 2+ limbs)
    assert sum(len(r) - 1 for r in rows) == len(coco_sample.skeleton.limbs)  # each limb once
    with pytest.raises(ValueError, match="limb_format"):
        write_gttnet_json(coco_sample, tmp_path / "x.json", limb_format="csv")


def _ptz_file(tmp_path, sample, *, with_camid: bool = True) -> tuple:
    """An authors'-layout file from pan-tilt-zoom cameras: each image has its own centre and rays.

    Two cameras circle the subject (a centre per image), so over the capture each camera looks in every
    direction: no single rotation keeps all of its rays in front of it.
    """
    obs, gt = make_view(sample, "full")
    X = gt.points3d  # (N, P, 3) metres, true time order
    n, p = X.shape[:2]
    cam = np.arange(n) % 2
    phase = np.linspace(0.0, 2.0 * np.pi, n) + np.pi * cam
    root = np.nanmean(X, axis=1)
    C = root + np.stack([6.0 * np.cos(phase), 6.0 * np.sin(phase), np.full(n, 1.5)], axis=1)
    rays = X - C[:, None, :]
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    rays[~obs.visible] = 0.0
    d = {
        "K": 0,
        "C": C.T.tolist(),
        "ray": rays.transpose(1, 2, 0).reshape(3 * p, n).tolist(),
        "point3D": X.transpose(1, 2, 0).reshape(3 * p, n).tolist(),
        "t": np.arange(n, dtype=float).tolist(),
        "limbSeq": adjacency_lists(sample.skeleton.limbs + 1),
        "units": "m",
    }
    if with_camid:
        d["camID"] = (cam + 1).tolist()
    path = tmp_path / "ptz.json"
    path.write_text(json.dumps(d))
    return path, rays, C, obs.visible


def test_pan_tilt_cameras_with_a_centre_per_image_import_exactly(tmp_path, coco_sample):
    path, rays, C, visible = _ptz_file(tmp_path, coco_sample)
    loaded = load_input(path, sequencing="none")
    obs = loaded.observations
    order = np.argsort(loaded.ground_truth.global_order)  # the view permutes images; undo it
    np.testing.assert_allclose(obs.rays()[order][visible], rays[visible], atol=1e-9)
    np.testing.assert_allclose(obs.centers()[order], C, atol=1e-9)
    assert len(np.unique(obs.cam_id)) == 2


def test_pan_tilt_capture_reconstructs_with_its_times(tmp_path, coco_sample):
    """The imported per-image poses are the true ones: HPF on the file's times recovers the structure.

    (24 noise-free images from two circling cameras: 9 mm; a wrong pose per image would be metres off.)
    """
    from gttnet.evaluate.metrics import mpjpe_mm
    from gttnet.methods import reconstruct

    path, *_ = _ptz_file(tmp_path, coco_sample)
    loaded = load_input(path, sequencing="full")
    rec = reconstruct(loaded.observations, "hpf")
    err = mpjpe_mm(rec.points3d, loaded.ground_truth.points3d)
    assert np.isfinite(err) and err < 30.0, err


def test_absent_camid_groups_images_by_centre_with_a_warning(tmp_path, coco_sample):
    path = write_gttnet_json(coco_sample, tmp_path / "cap.json")
    d = json.loads(path.read_text())
    cams = d.pop("camID")
    d.pop("K")  # absent K: rays only, as K = 0
    path.write_text(json.dumps(d))
    with pytest.warns(UserWarning, match="no 'camID' field"):
        cap = read_gttnet_json(path)
    # Same grouping as the stored ids (numbering may differ): a bijection between the two labelings.
    pairs = set(zip(cap.cam_id.tolist(), cams, strict=True))
    assert len(pairs) == len(set(cams)) == coco_sample.n_cameras


_JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-3, 40) | st.floats(allow_nan=True) | st.text(max_size=3),
    lambda inner: st.lists(inner, max_size=4),
    max_leaves=12,
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    key=st.sampled_from(["limbSeq", "camID", "C", "K", "t", "ray", "point3D", "units"]), value=_JSON_VALUES
)
def test_malformed_fields_are_one_line_never_a_crash(tmp_path_factory, coco_json, key, value):
    """Any JSON value in any field: either a capture or one ImportFormatError line naming file and field."""
    d = dict(coco_json)
    d[key] = value
    path = tmp_path_factory.mktemp("fuzz") / "cap.json"
    path.write_text(json.dumps(d))
    try:
        read_gttnet_json(path, units="m" if key != "units" else None)
    except ImportFormatError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(path) in msg
    except UserWarning:
        pass


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    drop=st.sets(st.sampled_from(["limbSeq", "camID", "C", "K", "t", "ray", "point3D", "units"]), max_size=3)
)
def test_absent_fields_are_optional_or_named(tmp_path_factory, coco_json, drop):
    d = {k: v for k, v in coco_json.items() if k not in drop}
    path = tmp_path_factory.mktemp("drop") / "cap.json"
    path.write_text(json.dumps(d))
    required = {"ray", "C"} & drop
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if required:
            with pytest.raises(ImportFormatError, match=f"field '({'|'.join(required)})'"):
                read_gttnet_json(path)
        else:
            assert read_gttnet_json(path).n_images == len(coco_json["C"][0])


@pytest.fixture(scope="module")
def coco_json(tmp_path_factory, coco_sample):
    path = write_gttnet_json(coco_sample, tmp_path_factory.mktemp("coco") / "cap.json")
    return json.loads(path.read_text())


@pytest.mark.parametrize("limbs", ["adjacency", "pairs"])
def test_cli_export_json_layouts_round_trip(tmp_path, limbs):
    """``gttnet export-json`` writes the authors' layout (either limb form) and reconstruct reads it back."""
    from gttnet.cli import main

    out = tmp_path / "authors_layout.json"
    args = ["export-json", "recipes/gttdata/tiny_topologies.yaml", "--split", "test", "--limbs", limbs]
    res = CliRunner().invoke(main, [*args, "--out", str(out)])
    assert res.exit_code == 0, res.output
    rows = json.loads(out.read_text())["limbSeq"]
    assert limbs == "adjacency" or all(len(r) == 2 for r in rows)
    res = CliRunner().invoke(
        main, ["reconstruct", str(out), "--method", "dloe", "--sequencing", "none", "--json"]
    )
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert np.isfinite(summary["mpjpe_mm"])
