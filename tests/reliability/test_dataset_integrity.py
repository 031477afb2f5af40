"""Item 1 (a manifest blesses only verified shards) and item 9's dataset messages."""

from __future__ import annotations

import json
import shutil

import h5py
from click.testing import CliRunner

from gttdata.cli import main
from tests.reliability.conftest import one_line_error


def _flip_in_chunk(path, field="keypoints_px"):
    """Flip one byte inside the stored chunk of sample 0's ``field`` (found through the HDF5 index)."""
    with h5py.File(path, "r") as f:
        ds = f["samples"][sorted(f["samples"])[0]][field]
        info = ds.id.get_chunk_info(0)
        offset = info.byte_offset + info.size // 2
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x01
    path.write_bytes(bytes(data))


def test_manifest_refuses_a_shard_whose_chunk_checksum_fails(tiny_data, tmp_path):
    """Reproduction: flip a byte in a chunk, delete the manifest, rebuild it, verify: it said OK."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    _flip_in_chunk(root / "train/shard-00000.h5")
    (root / "manifest.json").unlink()
    line = one_line_error(CliRunner().invoke(main, ["manifest", str(root)]))
    assert "train/shard-00000.h5" in line and "--resume" in line
    assert not (root / "manifest.json").exists()
    res = CliRunner().invoke(main, ["verify", str(root)])
    assert res.exit_code != 0 and "OK" not in res.output


def test_manifest_of_intact_shards_verifies(tiny_data, tmp_path):
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    (root / "manifest.json").unlink()
    assert CliRunner().invoke(main, ["manifest", str(root)]).exit_code == 0
    assert (root / "manifest.json").read_bytes() == (tiny_data / "manifest.json").read_bytes()


def test_missing_shard_names_the_file(tiny_data, tmp_path):
    """It said 'Error: None: Unable to synchronously open file'."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    (root / "train/shard-00000.h5").unlink()
    args = [
        "preview",
        str(root),
        "--split",
        "train",
        "--out",
        str(tmp_path / "p"),
    ]  # --split defaults to test
    line = one_line_error(CliRunner().invoke(main, args))
    assert "None" not in line and "train/shard-00000.h5" in line


def test_verify_json_reports_ok_and_problems(tiny_data, tmp_path):
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    res = CliRunner().invoke(main, ["verify", str(root), "--json"])
    report = json.loads(res.output)
    assert res.exit_code == 0 and report["ok"] and report["problems"] == [] and report["shards"] >= 1
    _flip_in_chunk(root / "train/shard-00000.h5")
    res = CliRunner().invoke(main, ["verify", str(root), "--json"])
    report = json.loads(res.output)
    assert res.exit_code == 1 and not report["ok"]
    assert any("train/shard-00000.h5" in p for p in report["problems"])
