"""Issue 29 D1, D2: a file from someone else never runs code, whatever loader reads it.

Each test plants a pickle whose ``__reduce__`` would create a marker file when unpickled, checks
that the payload is live (an unsafe load does create the marker), then hands the file to the
project's loader: the marker must stay absent and the refusal must be one line naming the file.
"""

from __future__ import annotations

import io
import pathlib
import pickle

import h5py
import numpy as np
import pytest
import torch
from click.testing import CliRunner
from hypothesis import given
from hypothesis import strategies as st

from gttdata.errors import KeypointFormatError
from gttnet.errors import ModelError
from gttnet.model.files import save_checked
from tests.reliability.conftest import one_line_error


class Payload:
    """Unpickling it calls ``Path.touch(marker)``: proof that a loader ran code from a file."""

    def __init__(self, marker: pathlib.Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path(self.marker),))


def _assert_live(tmp_path: pathlib.Path) -> None:
    """The payload does run under an unrestricted load (else the tests below prove nothing)."""
    control = tmp_path / "CONTROL"
    torch.load(io.BytesIO(_evil_torch_bytes(control)), weights_only=False)
    assert control.exists()
    control.unlink()


def _evil_torch_bytes(marker: pathlib.Path) -> bytes:
    buf = io.BytesIO()
    torch.save({"format": "gttnet-checkpoint/3", "model": {"w": torch.zeros(2)}, "x": Payload(marker)}, buf)
    return buf.getvalue()


def _one_line(exc: Exception, name: str) -> str:
    text = str(exc)
    assert "\n" not in text and name in text, text
    return text


# --- D1: checkpoints, models, item caches -----------------------------------------------------------


def test_checkpoint_with_code_is_refused_by_resume(tmp_path):
    """``gttnet train --out RUN --resume``: a checkpoint with a valid checksum header but a code payload."""
    from gttnet.cli import main
    from gttnet.train.checkpoint import load_checkpoint

    marker = tmp_path / "MARKER"
    data = _evil_torch_bytes(marker)
    _assert_live(tmp_path)
    run = tmp_path / "run"
    run.mkdir()
    save_checked(run / "checkpoint.pt", {"unused": 0})  # then swap in the payload with its own checksum
    import hashlib

    header = f"GTT-CHECKPOINT sha256={hashlib.sha256(data).hexdigest()} bytes={len(data)}\n".encode()
    (run / "checkpoint.pt").write_bytes(header + data)
    with pytest.raises(ModelError) as err:
        load_checkpoint(run)
    assert "pickled call to getattr" in _one_line(err.value, "checkpoint.pt") and not marker.exists()
    line = one_line_error(CliRunner().invoke(main, ["train", "--out", str(run), "--resume"]))
    assert "checkpoint.pt" in line and "refused" in line
    assert not marker.exists()


@pytest.mark.parametrize("layout", ["checksummed", "bare"])
def test_model_option_refuses_code(tmp_path, tiny_data, layout):
    """``gttnet reconstruct --model``: a GTT-CHECKPOINT file, or a ``checkpoint.pt`` with no card."""
    from gttnet.cli import main

    marker = tmp_path / "MARKER"
    data = _evil_torch_bytes(marker)
    _assert_live(tmp_path)
    path = tmp_path / "checkpoint.pt"
    if layout == "checksummed":
        save_checked(path, {"x": 0})
        import hashlib

        path.write_bytes(
            f"GTT-CHECKPOINT sha256={hashlib.sha256(data).hexdigest()} bytes={len(data)}\n".encode() + data
        )
    else:
        path.write_bytes(data)
    shard = str(tiny_data / "test/shard-00000.h5")
    line = one_line_error(
        CliRunner().invoke(main, ["reconstruct", shard, "--method", "gttnet", "--model", str(path)])
    )
    assert "checkpoint.pt" in line and "refused" in line
    assert not marker.exists()


def test_model_file_with_a_matching_card_still_refuses_code(tmp_path):
    """A card's checksum proves integrity, not origin: a model file with a true card is read weights only."""
    import hashlib
    import json

    from gttnet.model import inference

    marker = tmp_path / "MARKER"
    data = _evil_torch_bytes(marker)
    path = tmp_path / "m.pt"
    path.write_bytes(data)
    card = {"file": "m.pt", "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()}
    path.with_suffix(".json").write_text(json.dumps(card))
    with pytest.raises(ModelError) as err:
        inference.load_model(path)
    _one_line(err.value, "m.pt")
    assert not marker.exists()


def test_checkpoints_hold_only_weights_only_types(tmp_path):
    """What save_checkpoint writes needs no global outside torch's weights-only set (so it loads)."""
    from gttnet.model.network import build_model
    from gttnet.train.checkpoint import LoopState, load_checkpoint, save_checkpoint, set_rng_states

    model = build_model("gttnet_tiny", n_joints=5, k=6)
    save_checkpoint(
        tmp_path, model=model, optimizer=torch.optim.Adam(model.parameters()), state=LoopState(), recipe={}
    )
    raw = (tmp_path / "checkpoint.pt").read_bytes()
    body = tmp_path / "body.pt"
    body.write_bytes(raw[raw.index(b"\n") + 1 :])
    assert torch.serialization.get_unsafe_globals_in_checkpoint(str(body)) == []
    np.random.seed(7)  # noqa: NPY002
    expected = np.random.rand(3)  # noqa: NPY002
    np.random.seed(7)  # noqa: NPY002
    from gttnet.train.checkpoint import rng_states

    saved = rng_states()
    save_checked(tmp_path / "r.pt", {"rng": saved})
    np.random.seed(0)  # noqa: NPY002
    from gttnet.model.files import load_checked

    restored = load_checked(tmp_path / "r.pt")["rng"]
    set_rng_states(restored)
    assert np.array_equal(np.random.rand(3), expected)  # noqa: NPY002
    assert load_checkpoint(tmp_path)["state"].global_step == 0


def test_format2_checkpoint_with_numpy_state_still_resumes(tmp_path):
    """Checkpoints written before format 3 (NumPy state as an ndarray) load through the numpy allow-list."""
    from gttnet.model.files import load_checked
    from gttnet.train.checkpoint import set_rng_states

    np.random.seed(11)  # noqa: NPY002
    state = np.random.get_state()  # noqa: NPY002
    expected = np.random.rand(2)  # noqa: NPY002
    import random

    save_checked(tmp_path / "old.pt", {"rng": {"python": random.getstate(), "numpy": state,
                                              "torch": torch.get_rng_state()}})  # fmt: skip
    set_rng_states(load_checked(tmp_path / "old.pt")["rng"])
    assert np.array_equal(np.random.rand(2), expected)  # noqa: NPY002


def test_item_cache_with_code_is_rebuilt_not_run(tmp_path, caplog):
    """``item_cache/*.pt``: a planted entry is refused (one warning line) and rebuilt from the data."""
    from gttdata.recipe import load_recipe
    from gttnet.data import RecipeSource, SequenceDataset, load_item
    from tests.reliability.conftest import TINY

    src = RecipeSource(load_recipe(TINY), "train")
    cache = tmp_path / "item_cache"
    ds = SequenceDataset(src, k=6, sequencing={"none": 1.0}, cache="disk", cache_dir=cache)
    good = ds[(0, 0, None)]
    (entry,) = cache.glob("*.pt")
    marker = tmp_path / "MARKER"
    buf = io.BytesIO()
    torch.save(Payload(marker), buf)
    _assert_live(tmp_path)
    entry.write_bytes(buf.getvalue())
    fresh = SequenceDataset(src, k=6, sequencing={"none": 1.0}, cache="disk", cache_dir=cache)
    with caplog.at_level("WARNING", logger="gttnet.data"):
        item = fresh[(0, 0, None)]
    assert not marker.exists()
    assert torch.equal(item.inputs.x_init, good.inputs.x_init)
    warned = [r.getMessage() for r in caplog.records if r.name == "gttnet.data"]
    assert len(warned) == 1 and entry.name in warned[0] and "\n" not in warned[0], warned
    assert torch.equal(load_item(entry).points3d, good.points3d)  # the entry was rewritten, weights only


# --- D2: DeepLabCut .h5 ------------------------------------------------------------------------------


def _dlc_frame(n: int = 4, parts=("nose", "tail"), individuals: tuple[str, ...] = ()):
    pd = pytest.importorskip("pandas")
    pytest.importorskip("tables")
    levels = ["scorer", *(["individuals"] if individuals else []), "bodyparts", "coords"]
    cols = []
    for ind in individuals or (None,):
        for p in parts:
            for c in ("x", "y", "likelihood"):
                cols.append(("S", *([ind] if ind else []), p, c))
    values = np.arange(n * len(cols), dtype=np.float64).reshape(n, len(cols)) / 7.0
    values[1, 0] = np.nan
    return pd.DataFrame(
        values, columns=pd.MultiIndex.from_tuples(cols, names=levels), index=range(10, 10 + n)
    )


@pytest.mark.parametrize("fmt", ["table", "fixed"])
def test_dlc_h5_written_by_pandas_round_trips(tmp_path, fmt):
    from gttdata.detectors.dlc import read_dlc

    df = _dlc_frame()
    df.to_hdf(tmp_path / "cam.h5", key="df_with_missing", format=fmt, mode="w")
    kp = read_dlc(tmp_path / "cam.h5")
    assert kp.joint_names == ("nose", "tail") and kp.frame.tolist() == [10, 11, 12, 13]
    np.testing.assert_array_equal(kp.xy[:, 0, 0], df[("S", "nose", "x")].to_numpy())
    np.testing.assert_array_equal(kp.xy[:, 1, 1], df[("S", "tail", "y")].to_numpy())
    np.testing.assert_array_equal(kp.score[:, 1], np.clip(df[("S", "tail", "likelihood")], 0, 1))


def test_dlc_h5_multi_animal_reads_the_first_individual(tmp_path):
    from gttdata.detectors.dlc import read_dlc

    df = _dlc_frame(individuals=("a1", "a2"))
    df.to_hdf(tmp_path / "cam.h5", key="df_with_missing", format="table", mode="w")
    kp = read_dlc(tmp_path / "cam.h5")
    np.testing.assert_array_equal(kp.xy[:, 1, 0], df[("S", "a1", "tail", "x")].to_numpy())


def test_dlc_h5_fixed_layout_written_by_h5py(tmp_path):
    """The fixed layout built by hand (no pandas, no PyTables): what the reader relies on, and no more."""
    from gttdata.detectors.dlc import read_dlc

    path = tmp_path / "cam.h5"
    values = np.array([[1.0, 2.0, 0.9, 3.0, 4.0, 0.2], [5.0, 6.0, 0.8, np.nan, np.nan, 0.0]])
    with h5py.File(path, "w") as fh:
        g = fh.create_group("df_with_missing")
        g.attrs.update({"pandas_type": b"frame", "nblocks": 1, "axis0_variety": b"multi",
                        "axis0_nlevels": 3, "block0_items_variety": b"multi", "block0_items_nlevels": 3})  # fmt: skip
        for key in ("axis0", "block0_items"):
            for i, (name, level, codes) in enumerate(
                [
                    ("scorer", [b"S"], [0] * 6),
                    ("bodyparts", [b"nose", b"paw"], [0, 0, 0, 1, 1, 1]),
                    ("coords", [b"likelihood", b"x", b"y"], [1, 2, 0, 1, 2, 0]),
                ]  # fmt: skip
            ):
                g.create_dataset(f"{key}_level{i}", data=np.array(level)).attrs.update(
                    {"name": name.encode(), "kind": b"string"}
                )
                g.create_dataset(f"{key}_label{i}", data=np.array(codes, dtype=np.int8))
        g.create_dataset("axis1", data=np.array([3, 4])).attrs["kind"] = b"integer"
        g.create_dataset("block0_values", data=values).attrs["transposed"] = 1
    kp = read_dlc(path)
    assert kp.joint_names == ("nose", "paw") and kp.frame.tolist() == [3, 4]
    np.testing.assert_array_equal(kp.xy[0], [[1.0, 2.0], [3.0, 4.0]])
    assert np.isnan(kp.xy[1, 1]).all() and kp.score[0].tolist() == [0.9, 0.2]


def test_dlc_h5_with_a_pickled_object_column_is_refused(tmp_path):
    """Fixed layout: an object column is a pickled VLArray that ``pandas.read_hdf`` would unpickle."""
    pd = pytest.importorskip("pandas")
    pytest.importorskip("tables")
    from gttdata.detectors.dlc import read_dlc

    marker = tmp_path / "MARKER"
    df = _dlc_frame(n=2)
    df[("S", "nose", "likelihood")] = pd.Series([Payload(marker), 1.0], dtype=object, index=df.index)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pandas' PerformanceWarning about pickling
        df.to_hdf(tmp_path / "cam.h5", key="df_with_missing", format="fixed", mode="w")
    pd.read_hdf(tmp_path / "cam.h5")  # live: the old reader runs the payload
    assert marker.exists()
    marker.unlink()
    with pytest.raises(KeypointFormatError) as err:
        read_dlc(tmp_path / "cam.h5")
    assert "refused" in _one_line(err.value, "cam.h5")
    assert not marker.exists()


def test_dlc_h5_with_a_pickled_attribute_global_is_refused(tmp_path):
    """Table layout: PyTables unpickles attributes; a forged ``non_index_axes`` must not run."""
    pd = pytest.importorskip("pandas")
    pytest.importorskip("tables")
    from gttdata.detectors.dlc import read_dlc

    path = tmp_path / "cam.h5"
    _dlc_frame().to_hdf(path, key="df_with_missing", format="table", mode="w")
    marker = tmp_path / "MARKER"
    with h5py.File(path, "a") as fh:
        fh["df_with_missing"].attrs["non_index_axes"] = np.bytes_(pickle.dumps([Payload(marker)], protocol=0))
    with pytest.raises(Exception):  # noqa: B017 - pandas fails after the payload ran
        pd.read_hdf(path)
    assert marker.exists()  # live: the old reader runs it
    marker.unlink()
    with pytest.raises(KeypointFormatError) as err:
        read_dlc(path)
    assert "non_index_axes" in _one_line(err.value, "cam.h5") and "refused" in str(err.value)
    assert not marker.exists()


def test_dlc_h5_that_is_not_hdf5_is_one_line(tmp_path):
    from gttdata.detectors.dlc import read_dlc

    (tmp_path / "cam.h5").write_bytes(b"not hdf5")
    with pytest.raises(KeypointFormatError) as err:
        read_dlc(tmp_path / "cam.h5")
    _one_line(err.value, "cam.h5")


# --- D12: cached motion files are checked before use ---------------------------------------------------


def test_damaged_cached_motion_is_refused_before_generate(tmp_path):
    """A ``cache:`` motion whose SHA-256 is not the published one: one line, nothing generated."""
    from gttdata.cli import main
    from gttdata.generate_plan import _expand

    cache = tmp_path / "cache"
    cache.mkdir()
    for name in ("01_01.bvh", "01_03.bvh"):
        (cache / name).write_text("HIERARCHY\nROOT Hips\n")  # not the CMU clip
    _expand.cache_clear()
    res = CliRunner().invoke(
        main,
        ["generate", "recipes/gttdata/cmu.yaml", "--out", str(tmp_path / "out"), "--no-progress"],
        env={"GTT_CACHE": str(cache)},
    )
    _expand.cache_clear()
    line = one_line_error(res)
    assert "01_01.bvh" in line and "sha256" in line and "gttdata motions fetch" in line
    assert not (tmp_path / "out" / "manifest.json").exists()
    shown = CliRunner().invoke(main, ["motions", "show", "01_01.bvh"], env={"GTT_CACHE": str(cache)})
    assert "warning: " in shown.output and "sha256" in shown.output  # shown, never passed off as the clip


def test_cached_motion_check_passes_the_published_bytes(tmp_path, monkeypatch):
    import hashlib

    from gttdata.errors import GttDataError
    from gttdata.mocap import fetch

    path = tmp_path / "01_01.bvh"
    path.write_bytes(b"the published clip")
    entry = fetch.MotionFile("01_01.bvh", "pkg", "x", hashlib.sha256(b"the published clip").hexdigest())
    monkeypatch.setattr(fetch, "MOTION_FILES", (entry,))
    fetch.check_cached(path, tmp_path)  # intact: used
    fetch.check_cached(tmp_path / "other.bvh", tmp_path)  # no published checksum: not checked here
    path.write_bytes(b"the published clap")
    with pytest.raises(GttDataError) as err:
        fetch.check_cached(path, tmp_path)
    _one_line(err.value, "01_01.bvh")


# --- D15: manifest shard paths stay inside the dataset -------------------------------------------------


@pytest.mark.parametrize(
    "bad",
    ["../outside.h5", "/etc/passwd", "test/../../x.h5", "./test/shard-00000.h5", "test//a.h5", "", ".."],
)
def test_manifest_shard_path_outside_the_dataset_is_refused(tmp_path, tiny_data, bad):
    import json
    import shutil

    from gttdata.cli import main

    data = tmp_path / "data"
    shutil.copytree(tiny_data, data)
    manifest = json.loads((data / "manifest.json").read_text())
    manifest["shards"][0]["path"] = bad
    (data / "manifest.json").write_text(json.dumps(manifest))
    for cmd in (["verify", str(data)], ["inspect", str(data)]):
        line = one_line_error(CliRunner().invoke(main, cmd))
        assert "manifest.json" in line and "shards[0].path" in line and repr(bad) in line, line


@given(st.lists(st.sampled_from(["a", "b.h5", ".", "..", "", "/", "\\", "x..y"]), min_size=1, max_size=6))
def test_any_accepted_shard_path_stays_inside(parts):
    """Property: whatever a manifest says, a path the check lets through joins to a file under the root."""
    import posixpath

    from gttdata.errors import ManifestError
    from gttdata.manifest import _check_shard_path

    path = "/".join(parts)
    try:
        _check_shard_path("m.json", 0, path)
    except ManifestError as exc:
        assert "\n" not in str(exc)
        return
    joined = posixpath.normpath(posixpath.join("/root/data", path))
    assert joined.startswith("/root/data/") and joined == "/root/data/" + path


_plain = st.recursive(
    st.none() | st.booleans() | st.integers() | st.text(max_size=8) | st.floats(allow_nan=False),
    lambda inner: (
        st.lists(inner, max_size=4) | st.tuples(inner, inner) | st.dictionaries(st.text(max_size=4), inner)
    ),
    max_leaves=12,
)


@given(_plain, st.integers(0, 5))
def test_plain_unpickle_reads_builtin_data_and_nothing_else(value, protocol):
    """Property: builtin data round-trips under every protocol; the same data holding any global is refused."""
    from gttdata.detectors.pandas_h5 import plain_unpickle

    assert plain_unpickle(pickle.dumps(value, protocol=protocol), where="a") == value
    with pytest.raises(KeypointFormatError, match="refused without running it"):
        plain_unpickle(pickle.dumps([value, pathlib.PurePosixPath("x")], protocol=protocol), where="a")
