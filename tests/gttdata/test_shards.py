"""ShardWriter / ShardReader: exact round trips, rollover, atomic files, schema refusal, corruption reports."""

from __future__ import annotations

import pickle

import h5py
import numpy as np
import pytest

from gttdata.augment.capture import camera_perturbation, global_rotation
from gttdata.errors import ShardFormatError
from gttdata.shards import ShardReader, ShardWriter
from gttdata.shards.schema import GT_TOLERANCE_M, SAMPLE_FIELDS, VARIANT_FIELDS, shard_file_name
from gttdata.shards.writer import variant_from_orig

_ARRAYS = [f.name for f in SAMPLE_FIELDS]


def _group(make, seed: int = 0):
    """A toy capture (3 cams, 5 joints, N = 24, 1 px noise, 20 % missing) and its two paper variants."""
    s = make(sigma_px=1.0, missing=0.2, seed=seed)
    s = s.replace(name=f"train/{seed:06d}")
    rng = np.random.default_rng(seed)
    return [s, global_rotation(s, rng), camera_perturbation(s, rng)]


def _assert_same(a, b):
    for key in _ARRAYS:
        x, y = getattr(a, key), getattr(b, key)
        assert x.dtype == y.dtype and x.shape == y.shape, key
        if key == "points3d":  # stored as float32 (docs/FORMAT.md): rounding only
            np.testing.assert_allclose(x, y, rtol=0, atol=GT_TOLERANCE_M)
            if a.variant == "orig":
                np.testing.assert_array_equal(x, y.astype(np.float32).astype(np.float64))
        else:
            np.testing.assert_array_equal(x, y, err_msg=key)
    assert (a.name, a.motion_name, a.variant, a.skeleton, a.meta) == (
        b.name,
        b.motion_name,
        b.variant,
        b.skeleton,
        b.meta,
    )


@pytest.fixture
def written(tmp_path, scene_factory):
    groups = [_group(scene_factory, k) for k in range(3)]
    with ShardWriter(tmp_path, split="train", max_samples=2, attrs={"recipe_hash": "abc"}) as w:
        for g in groups:
            w.write(g)
    return tmp_path, groups, w.finished


def test_round_trip_every_variant(written):
    root, groups, _ = written
    r = ShardReader(root / "shard-00000.h5")
    assert len(r) == 2 and r.variants(1) == ("orig", "global_rotation", "camera_perturbation")
    for i in range(2):
        for ref in groups[i]:
            _assert_same(r.read_sample(i, ref.variant), ref)
    assert r.attrs["recipe_hash"] == "abc" and r.attrs["split"] == "train"


def test_rollover_by_samples_and_indices(written):
    root, groups, finished = written
    assert [f.path.name for f in finished] == ["shard-00000.h5", "shard-00001.h5"]
    assert [(f.first_index, f.n_samples) for f in finished] == [(0, 2), (2, 1)]
    r = ShardReader(root / "shard-00001.h5")
    assert r.sample_index(0) == 2 and r.attrs["first_index"] == 2
    _assert_same(r.read_sample(0), groups[2][0])
    assert not list(root.glob("*.tmp"))


def test_rollover_by_bytes_keeps_content(tmp_path, scene_factory):
    groups = [_group(scene_factory, k) for k in range(3)]
    with ShardWriter(tmp_path, split="t", max_samples=100, max_bytes=1, parts=True, shard_index=4) as w:
        for g in groups:
            w.write(g)
    names = [f.path.name for f in w.finished]
    assert (
        names
        == [shard_file_name(4), shard_file_name(4, 1), shard_file_name(4, 2)]
        == [
            "shard-00004.h5",
            "shard-00004.p1.h5",
            "shard-00004.p2.h5",
        ]
    )
    _assert_same(ShardReader(tmp_path / names[2]).read_sample(0), groups[2][0])


def test_identical_input_gives_identical_bytes(tmp_path, scene_factory):
    g = _group(scene_factory, 5)
    for d in ("a", "b"):
        with ShardWriter(tmp_path / d, split="t") as w:
            w.write(g)
    assert (tmp_path / "a/shard-00000.h5").read_bytes() == (tmp_path / "b/shard-00000.h5").read_bytes()


def test_error_leaves_no_complete_looking_file(tmp_path, scene_factory):
    g = _group(scene_factory)
    with pytest.raises(RuntimeError, match="boom"), ShardWriter(tmp_path, split="t") as w:
        w.write(g)
        assert list(tmp_path.glob("*.h5.tmp")) and not list(tmp_path.glob("*.h5"))
        raise RuntimeError("boom")
    assert not list(tmp_path.iterdir())


def test_writer_refuses_variant_with_other_ground_truth(tmp_path, scene_factory):
    orig, rot, _ = _group(scene_factory)
    bad = rot.replace(points3d=rot.points3d + 1e-3)
    with ShardWriter(tmp_path, split="t") as w, pytest.raises(ValueError, match="points3d must equal"):
        w.write([orig, bad])
    with (
        ShardWriter(tmp_path, split="t") as w,
        pytest.raises(ValueError, match="first sample must be variant 'orig'"),
    ):
        w.write([rot])


def test_variant_transform_is_stored(written):
    root, groups, _ = written
    r = ShardReader(root / "shard-00000.h5")
    T = r.file["samples/000000/variants/global_rotation/variant_from_orig"][()]
    np.testing.assert_array_equal(T, variant_from_orig(groups[0][1]))
    assert {f.name for f in VARIANT_FIELDS} == set(r.file["samples/000000/variants/global_rotation"].keys())


def test_large_coordinates_keep_float64(tmp_path, scene_factory):
    """Far from the origin float32 would lose more than 1e-6 m, so the writer keeps float64."""
    s = scene_factory()
    far = s.replace(points3d=s.points3d + 1000.0)
    with ShardWriter(tmp_path, split="t") as w:
        w.write(far)
    r = ShardReader(tmp_path / "shard-00000.h5")
    assert r.file["samples/000000/points3d"].dtype == np.float64
    np.testing.assert_array_equal(r.read_sample(0).points3d, far.points3d)


def test_reader_is_lazy_and_picklable(written):
    root, groups, _ = written
    r = ShardReader(root / "shard-00000.h5")
    assert r._file is None
    len(r)
    r2 = pickle.loads(pickle.dumps(r))
    assert r2._file is None
    _assert_same(r2.read_sample(-1), groups[1][0])


def test_index_and_variant_errors(written):
    root, _, _ = written
    r = ShardReader(root / "shard-00000.h5")
    with pytest.raises(IndexError, match="out of range for 2"):
        r.read_sample(2)
    with pytest.raises(KeyError, match="no variant 'nope'; stored: orig, global_rotation"):
        r.read_sample(0, "nope")


@pytest.mark.parametrize(("version", "ok"), [("1.7", True), ("2.0", False), (None, False), ("x", False)])
def test_schema_version_refusal(written, version, ok):
    root, _, _ = written
    path = root / "shard-00000.h5"
    with h5py.File(path, "a") as f:
        if version is None:
            del f.attrs["schema_version"]
        else:
            f.attrs["schema_version"] = version
    r = ShardReader(path)
    if ok:
        assert len(r) == 2
    else:
        with pytest.raises(ShardFormatError, match="shard-00000.h5: .*(schema_version|major)"):
            len(r)


def _chunk_offset(path, dataset):
    with h5py.File(path, "r") as f:
        ds = f[dataset]
        info = ds.id.get_chunk_info(0)
        return info.byte_offset + info.size // 2


def test_bit_flip_names_shard_sample_and_field(written):
    root, _, _ = written
    path = root / "shard-00000.h5"
    off = _chunk_offset(path, "samples/000001/keypoints_px")
    data = bytearray(path.read_bytes())
    data[off] ^= 0x10
    path.write_bytes(bytes(data))
    r = ShardReader(path)
    r.read_sample(0)  # other samples stay readable
    with pytest.raises(
        ShardFormatError, match=r"shard-00000.h5: sample 1 \(group samples/000001\): field 'keypoints_px'"
    ):
        r.read_sample(1)
    with pytest.raises(ShardFormatError, match="sample 1"):
        r.check()


def test_truncated_shard_is_reported(written):
    root, _, _ = written
    path = root / "shard-00000.h5"
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ShardFormatError, match="shard-00000.h5: (cannot open shard|sample)"):
        ShardReader(path).read_sample(0)


def test_not_a_shard(tmp_path):
    path = tmp_path / "x.h5"
    path.write_text("hello")
    with pytest.raises(ShardFormatError, match="x.h5: cannot open shard"):
        len(ShardReader(path))
