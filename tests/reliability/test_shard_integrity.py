"""Items D6 and D7 of issue 29: a shard's attribute text is checksummed, and damaged HDF5 metadata is one line.

D6: the text of every attribute (sample metadata, skeletons, recipe, statistics) lives in HDF5's global
heap, which neither HDF5's object-header checksums nor our Fletcher-32 chunks cover: 10 of 305 byte
flips passed ``manifest``, ``generate --resume`` and ``verify --deep``. D7: a truncated shard or a
garbage object header made ``manifest`` and ``generate --resume`` end in a traceback.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import pytest
from click.testing import CliRunner

from gttdata.cli import main
from gttdata.errors import ShardFormatError
from gttdata.fileio import file_sha256
from gttdata.shards.reader import ShardReader
from tests.reliability.conftest import TINY, one_line_error

SHARD = "train/shard-00000.h5"


def _texts(path: Path) -> dict[str, list[bytes]]:
    """Attribute texts of a shard by kind (each occurs once per group that holds it)."""
    with h5py.File(path, "r") as f:
        groups = [f["samples"][name] for name in sorted(f["samples"])]
        return {
            "sample metadata": [g.attrs["meta"].encode() for g in groups],
            "skeleton": [f.attrs["skeleton"].encode()] + [g.attrs["skeleton"].encode() for g in groups],
            "recipe": [f.attrs["recipe"].encode()],
            "stats": [f.attrs["stats"].encode()],
        }


def _offsets(raw: bytes, texts: list[bytes], per_text: int) -> list[int]:
    """Byte offsets spread over every stored copy of ``texts`` (first and last byte included)."""
    found: set[int] = set()
    for text in set(texts):
        start = raw.find(text)
        assert start >= 0, "attribute text is stored verbatim in the file"
        while start >= 0:
            n = len(text)
            found.update(start + round(k * (n - 1) / (per_text - 1)) for k in range(per_text))
            start = raw.find(text, start + 1)
    return sorted(found)


def _flipped(raw: bytes, offset: int, mask: int = 0x04) -> bytes:
    data = bytearray(raw)
    data[offset] ^= mask
    return bytes(data)


@pytest.mark.parametrize("kind", ["sample metadata", "skeleton", "recipe", "stats"])
def test_every_flip_in_attribute_text_is_detected(tiny_data, tmp_path, kind):
    """Flips spread over each stored copy of the text; on main about half of them read back as valid."""
    src = tiny_data / SHARD
    raw = src.read_bytes()
    offsets = _offsets(raw, _texts(src)[kind], per_text=16)
    assert len(offsets) >= 16
    path = tmp_path / "shard-00000.h5"
    missed = []
    for off in offsets:
        path.write_bytes(_flipped(raw, off))
        try:
            with ShardReader(path) as reader:
                reader.check()
        except ShardFormatError:
            continue
        missed.append(off)
    assert not missed, f"{len(missed)} of {len(offsets)} flips in {kind} passed the deep check: {missed}"


def _sigma_flip(raw: bytes, src: Path) -> bytes:
    """The issue's example: sample 0's ``sigma_px`` 1.0 becomes 5.0 (0x31 ^ 0x04 = '5')."""
    meta = _texts(src)["sample metadata"][0]
    at = meta.find(b'"sigma_px":1.0')
    assert at >= 0, meta
    return _flipped(raw, raw.find(meta) + at + len(b'"sigma_px":'))


def _vouch(root: Path, rel: str) -> None:
    """Make manifest.json vouch for the file's current bytes (as a manifest rebuilt after the damage did)."""
    path = root / "manifest.json"
    data = json.loads(path.read_text())
    for shard in data["shards"]:
        if shard["path"] == rel:
            shard["bytes"], shard["sha256"] = (root / rel).stat().st_size, file_sha256(root / rel)
    path.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")


def test_sigma_flip_is_caught_by_manifest_verify_deep_and_resume(tiny_data, tmp_path):
    """The issue's reproduction through the three commands (all three passed it before)."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    shard = root / SHARD
    shard.write_bytes(_sigma_flip(shard.read_bytes(), shard))
    with h5py.File(shard, "r") as f:  # the damage is what the issue saw: valid JSON, another value
        g = f["samples"][sorted(f["samples"])[0]]
        assert json.loads(g.attrs["meta"])["capture"]["sigma_px"] == 5.0

    (root / "manifest.json").rename(root / "good.json")
    line = one_line_error(CliRunner().invoke(main, ["manifest", str(root)]))
    assert SHARD in line and "attrs_sha256" in line and "--resume" in line
    assert not (root / "manifest.json").exists()

    (root / "good.json").rename(root / "manifest.json")
    _vouch(root, SHARD)
    res = CliRunner().invoke(main, ["verify", str(root)])
    assert res.exit_code == 0, res.output  # the manifest now vouches for these bytes ...
    res = CliRunner().invoke(main, ["verify", str(root), "--deep"])
    assert res.exit_code != 0 and SHARD in res.output and "attrs_sha256" in res.output  # ... deep does not

    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(root), "--resume", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert "4 samples kept" in res.output  # val and test kept, train regenerated
    assert shard.read_bytes() == (tiny_data / SHARD).read_bytes()


def _quiet_flip(text: bytes) -> int:
    """Offset in ``text`` of a flip that keeps it valid JSON: a digit or letter that stays one (mask 0x04)."""
    alnum = b"0123456789abcdefghijklmnopqrstuvwxyz"
    for i in range(len(text) // 2, len(text)):
        if text[i] in alnum and text[i] ^ 0x04 in alnum:
            changed = bytearray(text)
            changed[i] ^= 0x04
            try:
                json.loads(bytes(changed))
            except ValueError:
                continue
            return i
    raise AssertionError(text)


@pytest.mark.parametrize("kind", ["recipe", "stats", "skeleton"])
def test_manifest_and_resume_catch_a_flip_in_each_kind(tiny_data, tmp_path, kind):
    """One flip per kind of root text that leaves valid JSON, through ``manifest`` and ``--resume``."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    shard = root / SHARD
    raw = shard.read_bytes()
    text = _texts(shard)[kind][0]
    shard.write_bytes(_flipped(raw, raw.rfind(text) + _quiet_flip(text)))
    (root / "manifest.json").unlink()
    line = one_line_error(CliRunner().invoke(main, ["manifest", str(root)]))
    assert SHARD in line
    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(root), "--resume", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert shard.read_bytes() == (tiny_data / SHARD).read_bytes()


def test_a_flip_in_recipe_hash_is_damage_not_another_recipe(tiny_data, tmp_path):
    """``--resume`` refused the folder as holding 'another recipe'; the shard is damaged, so it is rebuilt."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    shard = root / SHARD
    raw = shard.read_bytes()
    with h5py.File(shard, "r") as f:
        digest = f.attrs["recipe_hash"].encode()
    shard.write_bytes(_flipped(raw, raw.find(digest) + 3, 0x01))
    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(root), "--resume", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert shard.read_bytes() == (tiny_data / SHARD).read_bytes()


def test_a_shard_without_the_checksum_is_refused_at_schema_1_2(tiny_data, tmp_path):
    path = tmp_path / "shard-00000.h5"
    shutil.copy(tiny_data / SHARD, path)
    with h5py.File(path, "r+") as f:
        del f.attrs["attrs_sha256"]
    with pytest.raises(ShardFormatError, match="attrs_sha256"), ShardReader(path) as reader:
        reader.check()


def test_a_schema_1_1_shard_reads_with_a_warning(tiny_data, tmp_path, caplog, monkeypatch):
    import gttdata.shards.reader as reader_mod

    monkeypatch.setattr(reader_mod, "_WARNED_UNCHECKED", [])  # shown once per process
    path = tmp_path / "shard-00000.h5"
    shutil.copy(tiny_data / SHARD, path)
    with h5py.File(path, "r+") as f:
        del f.attrs["attrs_sha256"]
        f.attrs["schema_version"] = "1.1"
    with ShardReader(path) as reader:
        reader.check()
    assert "warning: " in caplog.text and "no attribute checksum" in caplog.text


def test_resume_regenerates_a_schema_1_1_block(tiny_data, tmp_path):
    """A block without the checksum cannot be verified, so ``--resume`` writes it again."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    with h5py.File(root / SHARD, "r+") as f:
        del f.attrs["attrs_sha256"]
        f.attrs["schema_version"] = "1.1"
    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(root), "--resume", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert (root / SHARD).read_bytes() == (tiny_data / SHARD).read_bytes()


# -- D7: damaged HDF5 metadata ----------------------------------------------------------------------


def _damage(path: Path, how: str) -> None:
    raw = bytearray(path.read_bytes())
    if how == "truncated":
        raw = raw[: len(raw) // 2]
    elif how == "superblock":
        raw[:48] = b"\xa5" * 48
    elif how.startswith("object header"):  # the k-th v2 object header: signature kept, body garbage
        k = int(how.split()[-1])
        at = -1
        for _ in range(k + 1):
            at = raw.find(b"OHDR", at + 1)
        assert at > 0
        raw[at + 4 : at + 68] = b"\x5a" * 64
    elif how == "global heap":  # where variable-length attribute text lives
        at = raw.find(b"GCOL")
        raw[at : at + 64] = b"\x5a" * 64
    else:
        raise AssertionError(how)
    path.write_bytes(bytes(raw))


DAMAGE = ["truncated", "superblock", "object header 0", "object header 3", "object header 9", "global heap"]


@pytest.mark.parametrize("how", DAMAGE)
def test_damaged_metadata_is_one_line_and_resume_rebuilds_it(tiny_data, tmp_path, how):
    """``manifest`` names the shard and the remedy; the remedy (``--resume``) then works."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    _damage(root / SHARD, how)
    (root / "manifest.json").unlink()
    line = one_line_error(CliRunner().invoke(main, ["manifest", str(root)]))
    assert SHARD in line and "--resume" in line
    res = CliRunner().invoke(main, ["generate", TINY, "--out", str(root), "--resume", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert (root / SHARD).read_bytes() == (tiny_data / SHARD).read_bytes()
    assert CliRunner().invoke(main, ["verify", str(root), "--deep"]).exit_code == 0
