"""Items 7, 8 and 9: one-line errors for bad inputs and outputs, motion cache checksums and --force."""

from __future__ import annotations

import hashlib

from click.testing import CliRunner

import gttdata.mocap.fetch as fetch
from gttdata.cli import main as gttdata_main
from gttnet.cli import main as gttnet_main
from tests.reliability.conftest import one_line_error


def test_empty_mat_is_one_line(tmp_path):
    """It raised scipy's MatReadError traceback."""
    (tmp_path / "empty.mat").write_bytes(b"")
    line = one_line_error(CliRunner().invoke(gttnet_main, ["reconstruct", str(tmp_path / "empty.mat")]))
    assert "empty.mat" in line


def test_bad_out_suffix_is_refused_before_the_work(tiny_data, tmp_path, monkeypatch):
    """--out rec.txt failed only after the reconstruction had run."""
    import gttnet.io as gio

    def no_work(*a, **k):
        raise AssertionError("the input was read before --out was checked")

    monkeypatch.setattr(gio, "load_input", no_work)
    res = CliRunner().invoke(
        gttnet_main,
        ["reconstruct", str(tiny_data / "test/shard-00000.h5"), "--out", str(tmp_path / "rec.txt")],
    )
    line = one_line_error(res)
    assert "rec.txt" in line and ".h5" in line


def test_reconstruct_out_refuses_an_existing_file(tiny_data, tmp_path):
    out = tmp_path / "rec.h5"
    out.write_bytes(b"earlier result")
    shard = str(tiny_data / "test/shard-00000.h5")
    line = one_line_error(CliRunner().invoke(gttnet_main, ["reconstruct", shard, "--out", str(out)]))
    assert "--overwrite" in line and out.read_bytes() == b"earlier result"
    res = CliRunner().invoke(gttnet_main, ["reconstruct", shard, "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:4] == b"\x89HDF"


def test_reconstruct_full_disk_is_one_line(tiny_data, small_fs):
    """It segfaulted (exit 139) and left a .tmp file on a full disk."""
    (small_fs / "filler").write_bytes(b"\0" * (2 * 1024 * 1024 - 8192))
    out = small_fs / "rec.h5"
    shard = str(tiny_data / "train/shard-00000.h5")
    res = CliRunner().invoke(gttnet_main, ["reconstruct", shard, "--method", "pseudo", "--out", str(out)])
    line = one_line_error(res)
    assert str(out) in line and "no space left" in line
    assert not out.exists() and not [p for p in small_fs.iterdir() if p.name.endswith(".tmp")]


def _files(tmp_path, content=b"real motion bytes\n"):
    f = fetch.MotionFile(
        "walk.bvh", "fake-pkg", "usr/share/fake/walk.bvh", hashlib.sha256(content).hexdigest()
    )
    src = tmp_path / "sys" / f.member
    src.parent.mkdir(parents=True)
    src.write_bytes(content)
    return f, tmp_path / "sys"


def test_motions_fetch_replaces_a_damaged_cache(tmp_path, monkeypatch):
    """A truncated or garbage cached file was reported as 'already cached'."""
    f, root = _files(tmp_path)
    monkeypatch.setattr(fetch, "MOTION_FILES", (f,))
    monkeypatch.setattr(fetch, "SYSTEM_ROOT", root)
    cache = tmp_path / "cache"
    for damage in (b"real mot", b"garbage!!"):
        cache.mkdir(exist_ok=True)
        (cache / "walk.bvh").write_bytes(damage)
        res = CliRunner().invoke(gttdata_main, ["motions", "fetch", "--dest", str(cache)])
        assert res.exit_code == 0, res.output
        assert "damaged" in res.output and "already cached" not in res.output
        assert (cache / "walk.bvh").read_bytes() == b"real motion bytes\n"
    res = CliRunner().invoke(gttdata_main, ["motions", "fetch", "--dest", str(cache)])
    assert "already cached (sha256 verified)" in res.output
    res = CliRunner().invoke(gttdata_main, ["motions", "fetch", "--dest", str(cache), "--force"])
    assert res.exit_code == 0 and "copied" in res.output


def test_motions_fetch_refuses_a_source_with_the_wrong_checksum(tmp_path, monkeypatch):
    f, root = _files(tmp_path)
    (root / f.member).write_bytes(b"another version")
    monkeypatch.setattr(fetch, "MOTION_FILES", (f,))
    monkeypatch.setattr(fetch, "SYSTEM_ROOT", root)
    cache = tmp_path / "cache"
    line = one_line_error(CliRunner().invoke(gttdata_main, ["motions", "fetch", "--dest", str(cache)]))
    assert "sha256" in line and "walk.bvh" in line
    assert not list(cache.iterdir()), "nothing unverified enters the cache"


def test_nan_camera_centres_are_named(tmp_path):
    """NaN camera centres were reported as 'no triangulable joint'."""
    import json

    from gttdata.generate_plan import build_sample
    from gttdata.recipe import load_recipe
    from gttnet.io.gttnet_json import write_gttnet_json
    from tests.reliability.conftest import TINY

    path = write_gttnet_json(build_sample(load_recipe(TINY), "test", 0)[0], tmp_path / "cap.json")
    d = json.loads(path.read_text())
    d["C"][0][3] = float("nan")  # image 3's camera centre, x
    path.write_text(json.dumps(d))
    line = one_line_error(CliRunner().invoke(gttnet_main, ["reconstruct", str(path), "--method", "pseudo"]))
    assert "cap.json" in line and "cam_from_world" in line and "image" in line
    assert "triangulable" not in line
