"""Importers of the DLOE .mat and GTT-Net JSON layouts, shard input, sequencing views and output files."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import scipy.io

from gttdata.capture.sample import CaptureSample
from gttdata.capture.views import make_view
from gttnet.errors import ImportFormatError, SequencingError
from gttnet.io import detect_format, load_input
from gttnet.io.dloe_mat import read_dloe_mat
from gttnet.io.gttnet_json import read_gttnet_json
from gttnet.io.output import read_reconstruction, write_reconstruction
from gttnet.methods import Reconstruction

INCH = 0.0254


def _file_order(sample: CaptureSample) -> np.ndarray:
    """DLOE file order: grouped by camera, time-ordered inside each camera."""
    return np.lexsort((sample.timestamp_s, sample.cam_id))


def dloe_mat_dict(sample: CaptureSample) -> dict:
    """The DLOE demo layout of a sample, lengths in inches (the reference data's unit)."""
    idx = _file_order(sample)
    n, p = idx.shape[0], sample.n_joints
    R = sample.cam_from_world[:, :3, :3]
    C = -np.einsum("nji,nj->ni", R, sample.cam_from_world[:, :3, 3])

    def cells(items):
        out = np.empty((n, 1), dtype=object)
        for i, a in enumerate(items):
            out[i, 0] = a
        return out

    px = sample.keypoints_px.astype(np.float64)
    x = [np.vstack([px[i].T, np.ones((1, p))]) for i in idx]  # NaN pixels stay NaN
    counts = np.cumsum(np.bincount(sample.cam_id[idx]))
    order = np.argsort(sample.timestamp_s[idx], kind="stable") + 1  # file image numbers in time order
    caminput = {
        "x": cells(x),
        "K": cells(sample.K[idx]),
        "R": cells(R[idx]),
        "t": cells([C[i][None, :] / INCH for i in idx]),
        "cam_index": counts[None, :].astype(np.float64),
        "order": order[None, :].astype(np.float64),
    }
    X_GT = (sample.points3d[idx] / INCH).transpose(1, 2, 0).reshape(3 * p, n)  # joint-major rows
    return {"caminput": caminput, "X_GT": X_GT}


def write_dloe_mat(sample: CaptureSample, path, **edit) -> None:
    """Write a sample in the DLOE layout; ``edit`` replaces top-level or ``caminput_<field>`` entries."""
    d = dloe_mat_dict(sample)
    for k, v in edit.items():
        if k.startswith("caminput_"):
            if v is None:
                d["caminput"].pop(k[9:])
            else:
                d["caminput"][k[9:]] = v
        elif v is None:
            d.pop(k)
        else:
            d[k] = v
    scipy.io.savemat(str(path), d)


def gttnet_json_dict(sample: CaptureSample) -> dict:
    """The GTT-Net JSON layout (true time order, 1-based camera ids, inches)."""
    n, p = sample.n_images, sample.n_joints
    o = np.argsort(sample.timestamp_s, kind="stable")
    R = sample.cam_from_world[o, :3, :3]
    C = -np.einsum("nji,nj->ni", R, sample.cam_from_world[o, :3, 3])
    h = np.concatenate([sample.keypoints_px[o].astype(np.float64), np.ones((n, p, 1))], axis=-1)
    r = np.einsum("nba,njb->nja", R, np.einsum("nab,njb->nja", np.linalg.inv(sample.K[o]), h))
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    r = np.where(sample.visible[o][..., None], r, 0.0)
    V = sample.n_cameras
    first = [int(np.flatnonzero(sample.cam_id == c)[0]) for c in range(V)]
    return {
        "camID": (sample.cam_id[o] + 1).tolist(),
        "point3D": (sample.points3d[o] / INCH).transpose(1, 2, 0).reshape(3 * p, n).tolist(),
        "C": (C.T / INCH).tolist(),
        "K": np.concatenate([sample.K[i] for i in first], axis=1).tolist(),
        "ray": r.transpose(1, 2, 0).reshape(3 * p, n).tolist(),
        "A_GT": [[0]],
        "t": sample.timestamp_s[o].tolist(),
    }


def write_gttnet_json(sample: CaptureSample, path, **edit) -> None:
    """Write a sample in the GTT-Net JSON layout; ``edit`` replaces (or with None removes) keys."""
    d = gttnet_json_dict(sample)
    for k, v in edit.items():
        if v is None:
            d.pop(k)
        else:
            d[k] = v
    path.write_text(json.dumps(d))


@pytest.fixture
def noisy_sample(scene_factory) -> CaptureSample:
    """4 cameras, 6 joints, 6 frames each (N = 24), 1 px noise, 20 % joints missing."""
    return scene_factory(n_cameras=4, n_joints=6, frames_per_camera=6, sigma_px=1.0, missing=0.2, seed=3)


@pytest.mark.parametrize("sequencing", ["none", "partial", "full"])
@pytest.mark.parametrize("layout", ["mat", "json"])
def test_round_trip_matches_make_view(tmp_path, noisy_sample, layout, sequencing):
    path = tmp_path / f"cap.{layout}"
    (write_dloe_mat if layout == "mat" else write_gttnet_json)(noisy_sample, path)
    loaded = load_input(path, sequencing=sequencing, seed=5, units="inch")
    obs, gt = loaded.observations, loaded.ground_truth
    ref_obs, ref_gt = make_view(noisy_sample, "full")
    # Map every view image back to the sample by its true time rank.
    t = gt.global_order
    assert sorted(t.tolist()) == list(range(noisy_sample.n_images))
    np.testing.assert_allclose(gt.points3d, ref_gt.points3d[t], atol=1e-12)
    np.testing.assert_allclose(obs.rays(), ref_obs.rays()[t], atol=1e-6)
    np.testing.assert_array_equal(obs.visible, ref_obs.visible[t])
    np.testing.assert_allclose(obs.centers(), ref_obs.centers()[t], atol=1e-9)
    assert obs.sequencing == sequencing
    if sequencing == "full":
        np.testing.assert_array_equal(t, np.arange(noisy_sample.n_images))
        assert np.all(np.diff(obs.timestamp_s) > 0)
    elif sequencing == "partial":
        assert np.all(np.diff(obs.cam_id) >= 0)
        for c in np.unique(obs.cam_id):
            assert np.all(np.diff(t[obs.cam_id == c]) > 0)  # each stream in time order
        assert obs.timestamp_s is None
    else:
        assert obs.stream_index is None and obs.timestamp_s is None
        assert not np.array_equal(t, np.arange(noisy_sample.n_images))


def test_mat_pixels_and_units(tmp_path, noisy_sample):
    write_dloe_mat(noisy_sample, tmp_path / "a.mat")
    cap = read_dloe_mat(tmp_path / "a.mat", units="inch")
    idx = _file_order(noisy_sample)
    np.testing.assert_allclose(cap.keypoints_px, noisy_sample.keypoints_px[idx], atol=1e-4, equal_nan=True)
    np.testing.assert_allclose(cap.points3d, noisy_sample.points3d[idx], atol=1e-12)
    cap_cm = read_dloe_mat(tmp_path / "a.mat", units="cm")
    np.testing.assert_allclose(cap_cm.points3d, cap.points3d * (0.01 / INCH))
    np.testing.assert_array_equal(cap.image_size, noisy_sample.image_size)


@pytest.mark.parametrize("layout", ["mat", "json"])
def test_unrecorded_units_are_metres_with_a_warning(tmp_path, noisy_sample, layout):
    """An authors' file records no unit: metres are assumed and a warning names the file and --units inch."""
    path = tmp_path / f"cap.{layout}"
    (write_dloe_mat if layout == "mat" else write_gttnet_json)(noisy_sample, path)  # inches, unrecorded
    with pytest.warns(
        UserWarning, match=rf"^{path}: the .* layout records no length unit; assuming m; .*--units inch"
    ):
        guessed = load_input(path, sequencing="full")
    told = load_input(path, sequencing="full", units="inch")
    assert guessed.units == "m" and told.units == "inch"
    np.testing.assert_allclose(guessed.ground_truth.points3d, told.ground_truth.points3d / INCH, rtol=1e-12)


def test_recorded_units_are_used_and_a_contradiction_refused(tmp_path, noisy_sample):
    """A file that records its unit (our writer's ``units`` key) reads right with no warning and no --units."""
    path = tmp_path / "cap.json"
    write_gttnet_json(noisy_sample, path, units="inch")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        loaded = load_input(path, sequencing="full")
    assert loaded.units == "inch"
    np.testing.assert_allclose(
        loaded.ground_truth.points3d,
        noisy_sample.points3d[np.argsort(noisy_sample.timestamp_s, kind="stable")],
        atol=1e-12,
    )
    with pytest.raises(ImportFormatError, match=rf"^{path}: the file records units 'inch', --units says 'm'"):
        load_input(path, units="m")
    write_gttnet_json(noisy_sample, path, units="furlong")
    with pytest.raises(
        ImportFormatError, match=r"the file's units: expected one of m, mm, cm, inch, found 'furlong'"
    ):
        read_gttnet_json(path)


def test_mat_without_order_refuses_full(tmp_path, noisy_sample):
    write_dloe_mat(noisy_sample, tmp_path / "a.mat", caminput_order=0.0)
    loaded = load_input(tmp_path / "a.mat")
    assert loaded.observations.sequencing == "partial"
    assert np.all(loaded.ground_truth.global_order == -1)
    with pytest.raises(SequencingError, match="global image order"):
        load_input(tmp_path / "a.mat", sequencing="full")


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        ({"caminput_K": None}, r"caminput\.K'.*expected a field"),
        ({"caminput": None}, r"field 'caminput'.*expected a struct"),
        ({"X_GT": np.zeros((5, 5))}, r"field 'X_GT'.*expected shape \(3P, N\) = \(18, 24\), found \(5, 5\)"),
        ({"caminput_cam_index": np.array([[6.0, 12, 18, 23]])}, r"caminput\.cam_index'.*ending at N = 24"),
        ({"caminput_order": np.arange(1.0, 24)[None]}, r"caminput\.order'.*permutation of 1\.\.24"),
    ],
)
def test_mat_malformed(tmp_path, noisy_sample, edit, match):
    path = tmp_path / "bad.mat"
    write_dloe_mat(noisy_sample, path, **edit)
    with pytest.raises(ImportFormatError, match=match) as exc:
        load_input(path)
    assert str(path) in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        ({"ray": None}, r"field 'ray'.*no such key"),
        ({"C": [[0.0, 1.0]]}, r"field 'C'.*expected shape \(3, N\)"),
        ({"K": np.eye(3).tolist()}, r"field 'K'.*expected shape \(3, 3V\) = \(3, 12\)"),
        ({"point3D": [[1.0, 2.0]]}, r"field 'point3D'"),
        ({"camID": [[1, 2], [3, 4]]}, r"field 'camID'"),
    ],
)
def test_json_malformed(tmp_path, noisy_sample, edit, match):
    path = tmp_path / "bad.json"
    write_gttnet_json(noisy_sample, path, **edit)
    with pytest.raises(ImportFormatError, match=match) as exc:
        read_gttnet_json(path)
    assert str(path) in str(exc.value)


def test_json_non_unit_ray_and_bad_text(tmp_path, noisy_sample):
    d = gttnet_json_dict(noisy_sample)
    d["ray"][0][0] *= 2.0
    bad = tmp_path / "ray.json"
    bad.write_text(json.dumps(d))
    with pytest.raises(ImportFormatError, match="unit rays"):
        read_gttnet_json(bad)
    txt = tmp_path / "t.json"
    txt.write_text("{not json")
    with pytest.raises(ImportFormatError, match="line 1"):
        read_gttnet_json(txt)


def test_detect_format(tmp_path):
    assert detect_format("a/b.H5") == "h5" and detect_format("x.mat") == "dloe-mat"
    with pytest.raises(ImportFormatError, match="suffix '.txt'"):
        detect_format(tmp_path / "x.txt")


@pytest.fixture
def toy_shard(tmp_path, toy_sample):
    """One shard file holding ``toy_sample`` (split ``test``)."""
    writer = pytest.importorskip("gttdata.shards.writer")
    pytest.importorskip("gttdata.shards.reader")
    with writer.ShardWriter(tmp_path, split="test") as w:
        w.write(toy_sample)
    return sorted(tmp_path.glob("*.h5"))[0]


def test_shard_input(toy_shard, toy_sample):
    loaded = load_input(toy_shard, sequencing="partial")
    ref_obs, ref_gt = make_view(toy_sample, "partial")
    np.testing.assert_allclose(loaded.observations.rays(), ref_obs.rays(), atol=1e-6)
    np.testing.assert_array_equal(loaded.image_index, ref_gt.perm)


@pytest.mark.parametrize("suffix", [".h5", ".npz"])
def test_output_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(0)
    rec = Reconstruction(
        points3d=rng.normal(size=(5, 2, 3)),
        affinity=rng.random((5, 5)),
        order=np.array([4, 3, 2, 1, 0]),
        seconds=1.5,
        method="dloe",
        sequencing="partial",
        info={"iterations": 3},
    )
    path = write_reconstruction(
        rec, tmp_path / f"out{suffix}", image_index=np.arange(5)[::-1], source="in.mat"
    )
    arrays, attrs = read_reconstruction(path)
    np.testing.assert_array_equal(arrays["points3d"], rec.points3d)
    np.testing.assert_array_equal(arrays["affinity"], rec.affinity)
    np.testing.assert_array_equal(arrays["order"], rec.order)
    np.testing.assert_array_equal(arrays["image_index"], [4, 3, 2, 1, 0])
    assert attrs["method"] == "dloe" and attrs["sequencing"] == "partial" and attrs["units"] == "m"
    assert attrs["info"] == {"iterations": 3} and attrs["source"] == "in.mat"
    with pytest.raises(ValueError, match="suffix"):
        write_reconstruction(rec, tmp_path / "out.csv")


def test_shard_bad_sample_index(toy_shard):
    with pytest.raises(ImportFormatError, match="variant 'nope'"):
        load_input(toy_shard, variant="nope")
