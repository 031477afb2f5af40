"""End to end: ``gttdata generate`` -> ``verify`` -> ``inspect``; determinism, kill/resume, array jobs, one-line errors."""

from __future__ import annotations

import errno
import re
from pathlib import Path

import pytest
from click.testing import CliRunner

import gttdata.generation as generation
import gttdata.shards.writer as writer_mod
from gttdata.cli import main
from gttdata.shards.reader import ShardReader

pytestmark = pytest.mark.integration

TINY = "recipes/gttdata/tiny.yaml"  # 3 blocks: train (4 samples), val (2), test (2); ~0.2 s


def _run(*args: str, ok: bool = True):
    result = CliRunner().invoke(main, list(args))
    if ok:
        assert result.exit_code == 0, result.output + repr(result.exception)
    return result


def _files(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.glob("*/*.h5*"))}


def _one_error_line(result) -> str:
    assert result.exit_code == 1, result.output
    lines = [ln for ln in result.output.splitlines() if ln.startswith("Error:")]
    assert len(lines) == 1 and "Traceback" not in result.output, result.output
    return lines[0]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """An uninterrupted single-process run of the tiny recipe."""
    out = tmp_path_factory.mktemp("ref")
    _run("generate", TINY, "--out", str(out), "--no-progress")
    return out


def test_generate_verify_inspect(reference):
    assert (reference / "manifest.json").exists()
    assert sorted(_files(reference)) == ["test/shard-00000.h5", "train/shard-00000.h5", "val/shard-00000.h5"]
    out = _run("verify", str(reference)).output
    assert "OK (3 shards, 8 samples)" in out
    out = _run("inspect", str(reference)).output
    assert re.search(r"train\s+1\s+4\s+96", out) and "variants   orig, global_rotation" in out
    assert "radius 3 m" in out and "{" not in out and "PosixPath" not in out, out
    out = _run("inspect", str(reference / "train/shard-00000.h5"), "--sample", "2").output
    assert "sample 2: train/000002" in out and re.search(r"keypoints_px\s+24 x 31 x 2\s+float32", out)
    assert "(" not in out.split("sample 2:")[1], out  # no tuple reprs in the array table


def test_inspect_and_generate_json(reference, tmp_path):
    import json

    data = json.loads(_run("inspect", str(reference), "--json").output)
    assert data["dataset"] == "tiny" and data["splits"]["train"]["samples"] == 4
    assert data["splits"]["total"]["images"] == 192 and data["variants"] == ["orig", "global_rotation"]
    shard = json.loads(
        _run("inspect", str(reference / "test/shard-00000.h5"), "--sample", "1", "--json").output
    )
    arrays = {a["name"]: a for a in shard["sample"]["arrays"]}
    assert shard["split"] == "test" and arrays["points3d"]["shape"] == [24, 31, 3]
    gen = json.loads(_run("generate", TINY, "--out", str(tmp_path), "--no-progress", "--json").output)
    assert gen["splits"] == data["splits"] and gen["samples_written"] == 8 and gen["seconds"] > 0
    (tmp_path / "val/shard-00000.h5").unlink()  # a resume keeps 6 samples that verify and writes 2
    again = json.loads(
        _run("generate", TINY, "--out", str(tmp_path), "--resume", "--no-progress", "--json").output
    )
    assert (again["samples_written"], again["samples_kept"]) == (2, 6)
    text = _run("generate", TINY, "--out", str(tmp_path), "--resume", "--no-progress").output
    assert "nothing to write; 8 samples kept (they verify)" in text and "samples/s" not in text
    bad = _run("inspect", str(reference / "test/shard-00000.h5"), "--sample", "9", ok=False)
    assert bad.exit_code == 2 and "holds samples 0-1, got 9" in bad.output


def test_workers_give_identical_bytes(reference, tmp_path):
    out = _run("generate", TINY, "--out", str(tmp_path), "--workers", "2", "--no-progress").output
    assert "2 workers" in out
    assert _files(tmp_path) == _files(reference)


def test_array_jobs_then_last_job_writes_manifest(reference, tmp_path):
    first = _run("generate", TINY, "--out", str(tmp_path), "--shard-range", "0:1", "--no-progress").output
    assert "manifest is written by the job that completes" in first
    assert not (tmp_path / "manifest.json").exists()
    _run("generate", TINY, "--out", str(tmp_path), "--shard-range", "1:", "--no-progress")
    assert (tmp_path / "manifest.json").exists()
    assert _files(tmp_path) == _files(reference)
    _run("verify", str(tmp_path))


def test_kill_leaves_nothing_complete_looking_and_resume_finishes(reference, tmp_path, monkeypatch):
    calls = {"n": 0}
    real_build = generation.build_sample

    def dying_build(recipe, split, index):
        calls["n"] += 1
        if calls["n"] == 6:  # in the middle of the second block (val)
            raise KeyboardInterrupt
        return real_build(recipe, split, index)

    monkeypatch.setattr(generation, "build_sample", dying_build)
    monkeypatch.setattr(writer_mod.ShardWriter, "abort", lambda self: None)  # SIGKILL: no cleanup
    result = _run("generate", TINY, "--out", str(tmp_path), "--no-progress", ok=False)
    assert result.exit_code != 0
    monkeypatch.undo()
    assert not (tmp_path / "manifest.json").exists()
    assert list(tmp_path.glob("val/*.h5.tmp")), "the killed block stays a .tmp file"
    assert sorted(_files(tmp_path)) == ["train/shard-00000.h5", "val/shard-00000.h5.tmp"]
    ShardReader(tmp_path / "train/shard-00000.h5").check()  # every final-named file is complete
    _run("generate", TINY, "--out", str(tmp_path), "--resume", "--no-progress")
    assert _files(tmp_path) == _files(reference)
    _run("verify", str(tmp_path), "--deep")


def test_resume_regenerates_corrupt_shard(reference, tmp_path):
    _run("generate", TINY, "--out", str(tmp_path), "--no-progress")
    bad = tmp_path / "val/shard-00000.h5"
    data = bytearray(bad.read_bytes())
    data[len(data) // 2] ^= 0x04
    bad.write_bytes(bytes(data))
    assert _run("verify", str(tmp_path), ok=False).exit_code == 1
    _run("generate", TINY, "--out", str(tmp_path), "--resume", "--no-progress")
    assert _files(tmp_path) == _files(reference)


def test_verify_names_bad_shard(reference, tmp_path):
    import shutil

    root = tmp_path / "d"
    shutil.copytree(reference, root)
    (root / "test/shard-00000.h5").write_bytes(b"\0" * 10)
    result = _run("verify", str(root), ok=False)
    assert result.exit_code == 1
    assert "BAD test/shard-00000.h5: size: expected" in result.output
    assert "1 problem(s) in 3 shards" in result.output


def test_other_recipe_in_same_directory_is_refused(reference, tmp_path):
    _run("generate", TINY, "--out", str(tmp_path), "--no-progress")
    line = _one_error_line(
        _run("generate", TINY, "seed=99", "--out", str(tmp_path), "--no-progress", ok=False)
    )
    assert "already holds a dataset" in line and "--overwrite" in line
    line = _one_error_line(
        _run("generate", TINY, "seed=99", "--out", str(tmp_path), "--resume", "--no-progress", ok=False)
    )
    assert "recipe_hash" in line and "own output directory" in line
    _run("generate", TINY, "seed=99", "--out", str(tmp_path), "--overwrite", "--no-progress")
    _run("verify", str(tmp_path), "--deep")


def test_missing_motion_file_is_one_line(tmp_path):
    recipe = tmp_path / "r.yaml"
    recipe.write_text(
        "name: m\nsplits:\n  - name: train\n    n_samples: 1\n"
        "    sources: [{kind: files, paths: [/nonexistent/walk.bvh]}]\n"
    )
    line = _one_error_line(
        _run("generate", str(recipe), "--out", str(tmp_path / "o"), "--no-progress", ok=False)
    )
    assert "/nonexistent/walk.bvh" in line


def test_unwritable_output_is_one_line(tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("x")  # tests run as root: a path under a regular file is unwritable for anyone
    line = _one_error_line(_run("generate", TINY, "--out", str(blocker / "out"), "--no-progress", ok=False))
    assert "file.txt" in line and "Not a directory" in line


def test_full_disk_is_one_line_and_leaves_no_tmp(tmp_path, monkeypatch):
    def full(path):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(writer_mod, "_fsync_file", full)
    line = _one_error_line(_run("generate", TINY, "--out", str(tmp_path), "--no-progress", ok=False))
    assert "no space left on device" in line and "shard-00000.h5.tmp" in line
    assert not list(tmp_path.glob("*/*.h5*"))


def test_register_and_preview(tmp_path, monkeypatch):
    import gttdata.cli.generate as gen_cli

    manifests = tmp_path / "manifests"
    manifests.mkdir()
    monkeypatch.setattr(gen_cli, "repo_manifests_dir", lambda: manifests)
    out = _run(
        "generate", TINY, "--out", str(tmp_path / "d"), "--register", "--preview", "1", "--no-progress"
    )
    assert (manifests / "tiny.json").exists()
    assert "preview" in out.output


@pytest.mark.parametrize(
    ("rng", "message"), [("7:9", "selects none of the 3 blocks"), ("a:b", "expected 'a:b'")]
)
def test_bad_shard_range_is_one_line(tmp_path, rng, message):
    line = _one_error_line(_run("generate", TINY, "--out", str(tmp_path), "--shard-range", rng, ok=False))
    assert message in line
