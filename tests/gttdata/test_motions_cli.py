"""Tests for ``gttdata motions`` (fetch, list, show), the Debian fetcher behind it, and the fetched files."""

from __future__ import annotations

import gzip
import os
import shutil
import stat
import subprocess
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.cli import main
from gttdata.errors import GttDataError
from gttdata.mocap import fetch, load_motion
from gttdata.mocap.fetch import MOTION_FILES, cache_dir, fetch_motions, list_cached
from gttdata.skeleton import cmu31

_TINY_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Head
  {
    OFFSET 0 170 0
    CHANNELS 3 Zrotation Yrotation Xrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.04
0 0 0 0 0 0 0 0 0
10 0 0 0 0 0 0 0 0
20 0 0 0 0 0 0 0 0
"""


def _content(name: str) -> bytes:
    return _TINY_BVH.encode() if name.endswith(".bvh") else f"c3d bytes of {name}".encode()


def _fake_tree(root: Path, *, gzip_c3d: bool) -> Path:
    """Lay out the packaged files under ``root`` as the Debian packages do (C3D optionally gzipped)."""
    for f in MOTION_FILES:
        target = root / f.member
        target.parent.mkdir(parents=True, exist_ok=True)
        if gzip_c3d and f.name.endswith(".c3d"):
            target.with_name(target.name + ".gz").write_bytes(gzip.compress(_content(f.name)))
        else:
            target.write_bytes(_content(f.name))
    return root


@pytest.fixture(autouse=True)
def _unchecked_files(request, monkeypatch):
    """The fake trees hold made-up bytes: check no SHA-256 (tests/reliability checks the checksums)."""
    if "real" not in request.node.name:
        monkeypatch.setattr(fetch, "MOTION_FILES", tuple(replace(f, sha256=None) for f in MOTION_FILES))


@pytest.fixture
def fake_apt(tmp_path, monkeypatch) -> Path:
    """A PATH with a fake ``apt-get`` that "downloads" .deb files built here with the real dpkg-deb."""
    if shutil.which("dpkg-deb") is None:
        pytest.skip("dpkg-deb is not installed")
    debs = tmp_path / "debs"
    debs.mkdir()
    for package in ("assimp-testmodels", "dart-doc"):
        tree = tmp_path / "build" / package
        _fake_tree(tree, gzip_c3d=True)
        for f in MOTION_FILES:  # keep only this package's files
            if f.package != package:
                for p in (tree / f.member, tree / (f.member + ".gz")):
                    p.unlink(missing_ok=True)
        (tree / "DEBIAN").mkdir()
        (tree / "DEBIAN" / "control").write_text(
            f"Package: {package}\nVersion: 1.0\nArchitecture: all\nMaintainer: t <t@example.org>\nDescription: fake\n"
        )
        subprocess.run(["dpkg-deb", "--build", "--root-owner-group", str(tree), str(debs / f"{package}_1.0_all.deb")],
                       check=True, capture_output=True)  # fmt: skip
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    apt = bin_dir / "apt-get"
    apt.write_text(f'#!/bin/sh\n[ "$1" = download ] || exit 2\ncp "{debs}/$2"_*.deb . \n')
    apt.chmod(apt.stat().st_mode | stat.S_IEXEC)
    monkeypatch.setenv("PATH", f"{bin_dir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setattr(fetch, "SYSTEM_ROOT", tmp_path / "empty-root")
    return bin_dir


@pytest.mark.parametrize("gzip_c3d", [False, True])
def test_fetch_from_installed_tree_is_idempotent(tmp_path, gzip_c3d):
    root = _fake_tree(tmp_path / "sys", gzip_c3d=gzip_c3d)
    dest = tmp_path / "cache"
    paths = fetch_motions(dest, system_root=root)
    assert [p.name for p in paths] == [f.name for f in MOTION_FILES]
    for p in paths:
        assert p.read_bytes() == _content(p.name)
    (dest / "squat.c3d").write_bytes(b"kept")  # a second run must not touch cached files
    shutil.rmtree(root)
    fetch_motions(dest, system_root=root)
    assert (dest / "squat.c3d").read_bytes() == b"kept"
    assert not list(dest.glob("*.tmp"))


def test_fetch_downloads_with_apt_and_unpacks_gz(tmp_path, fake_apt):
    dest = tmp_path / "cache"
    paths = fetch_motions(dest)
    for p in paths:
        assert p.read_bytes() == _content(p.name)
    assert list_cached(dest) == sorted(paths)


def test_fetch_without_apt_is_one_clear_line(tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setattr(fetch, "SYSTEM_ROOT", tmp_path / "empty-root")
    with pytest.raises(GttDataError, match="apt-get not found") as e:
        fetch_motions(tmp_path / "cache")
    assert "\n" not in str(e.value)


def test_fetch_apt_failure_reports_its_message(tmp_path, monkeypatch):
    if shutil.which("dpkg-deb") is None:
        pytest.skip("dpkg-deb is not installed")
    apt = tmp_path / "apt-get"
    apt.write_text("#!/bin/sh\necho 'E: Unable to locate package' >&2\nexit 100\n")
    apt.chmod(0o755)
    monkeypatch.setenv("PATH", f"{tmp_path}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setattr(fetch, "SYSTEM_ROOT", tmp_path / "empty-root")
    result = CliRunner().invoke(main, ["motions", "fetch", "--dest", str(tmp_path / "cache")])
    assert result.exit_code == 1
    *progress, error = result.output.strip().splitlines()
    assert "apt-get download assimp-testmodels' failed (E: Unable to locate package)" in error
    assert error.startswith("Error: ") and all("Error" not in line for line in progress)


def test_cli_fetch_list_show(tmp_path, fake_apt, monkeypatch):
    cache = tmp_path / "gtt-cache"
    monkeypatch.setenv("GTT_CACHE", str(cache))
    runner = CliRunner()
    r = runner.invoke(main, ["motions", "list"])
    assert r.exit_code == 0 and "no motion files" in r.output
    r = runner.invoke(main, ["motions", "fetch"])
    assert r.exit_code == 0, r.output
    lines = r.output.strip().splitlines()
    assert (
        lines[0]
        == "assimp-testmodels: not installed; running 'apt-get download assimp-testmodels' and 'dpkg-deb -x'"
    )
    assert lines[-1] == f"{len(MOTION_FILES)} motion files in {cache}"
    assert sum("unpacked from" in line for line in lines) == len(MOTION_FILES)
    r = runner.invoke(main, ["motions", "fetch"])
    assert r.exit_code == 0 and r.output.count("already cached") == len(MOTION_FILES)
    r = runner.invoke(main, ["motions", "list"])
    assert r.exit_code == 0, r.output
    lines = r.output.strip().splitlines()
    assert lines[0].split() == ["file", "frames", "fps", "joints", "MB"]
    assert len(lines) == 1 + len(MOTION_FILES)
    # The fake BVH clips read as 3 frames, 25 Hz, 2 joints; the fake C3D bytes as unreadable, on one line.
    assert lines[1].split()[:4] == ["01_01.bvh", "3", "25", "2"]
    assert "nick_freeform_001.c3d" in lines[4] and "unreadable" in lines[4]
    # By cache name; the tiny clip: 3 frames at 25 Hz, 2 joints, head 1.7 m above the hips.
    r = runner.invoke(main, ["motions", "show", "01_01.bvh", "--scale", "0.01"])
    assert r.exit_code == 0, r.output
    for expected in (
        "frames: 3",
        "fps: 25",
        "joints: 2",
        "duration: 0.08 s",
        "x 200 mm",
        "standing height: 1.70 m",
    ):
        assert expected in r.output


@pytest.mark.parametrize(
    ("args", "exit_code", "expected"),
    [
        (["show", "{d}/clip.bvh", "--scale", "1"], 0, "frames: 3"),
        (["show", "{d}/clip.bvh", "--format", "bvh"], 0, "standing height: 1.70 m"),
        (["show", "{d}/clip.bvh", "--format", "c3d"], 1, "not a readable C3D file"),
        (["show", "{d}/clip.bvh", "--format", "xyz"], 1, "unknown motion format 'xyz'"),
        (["show", "{d}/missing.bvh"], 1, "motion file not found"),
        (["show", "{d}/bad.bvh"], 1, "line 17: expected 'Frames:"),
        (["show", "{d}/clip.bvh", "--format", "c3d", "--scale", "1"], 2, "--scale applies to BVH files only"),
        (
            ["show", "{d}/warn.bvh"],
            0,
            "warning: {d}/warn.bvh: header says 2 frames but the file holds 3 rows",
        ),
    ],
)
def test_cli_show_cases(tmp_path, args, exit_code, expected):
    (tmp_path / "clip.bvh").write_text(_TINY_BVH)
    (tmp_path / "bad.bvh").write_text(_TINY_BVH.replace("Frames: 3", "Frame 3"))
    (tmp_path / "warn.bvh").write_text(_TINY_BVH.replace("Frames: 3", "Frames: 2"))
    r = CliRunner().invoke(main, ["motions", *[a.format(d=tmp_path) for a in args]])
    assert r.exit_code == exit_code, r.output
    assert expected.format(d=tmp_path) in r.output
    if exit_code == 1:
        assert len(r.output.strip().splitlines()) == 1


@pytest.mark.mocap
def test_cli_show_real_cmu_clip(mocap_dir):
    r = CliRunner().invoke(main, ["motions", "show", str(mocap_dir / "01_01.bvh")])
    assert r.exit_code == 0, r.output
    for expected in ("frames: 2752", "fps: 120", "joints: 31 (skeleton cmu31)", "duration: 22.93 s"):
        assert expected in r.output
    height = float(r.output.split("standing height: ")[1].split(" m")[0])
    assert 1.3 < height < 1.9
    assert np.isfinite(height)


# Real fetched files, through the loaders.


@pytest.mark.mocap
def test_real_cmu_bvh(mocap_dir):
    m = load_motion(mocap_dir / "01_01.bvh")
    assert (m.n_frames, m.fps_hz, m.skeleton.n_joints) == (2752, 120.0, 31)
    assert m.skeleton == cmu31()
    lengths = m.bone_lengths()
    np.testing.assert_allclose(lengths, lengths[:1].repeat(len(lengths), 0), atol=1e-9)
    # Femur (hip to knee) of CMU subject 01 is 7.15 CMU units, about 0.40 m.
    assert 0.35 < lengths[0, list(m.skeleton.bones[:, 0]).index(3)] < 0.45
    assert -0.05 < np.percentile(m.positions[..., 2].min(axis=1), 50) < 0.15  # feet near the floor


@pytest.mark.mocap
def test_real_boxing_bvh_trusts_rows(mocap_dir):
    with pytest.warns(UserWarning, match="header says 3069 frames but the file holds 3070"):
        m = load_motion(mocap_dir / "Boxing_Toes.bvh")
    assert (m.n_frames, m.fps_hz, m.skeleton.n_joints) == (3070, 100.0, 21)


@pytest.mark.mocap
def test_real_c3d(mocap_dir):
    m = load_motion(mocap_dir / "squat.c3d")
    assert (m.fps_hz, m.skeleton.n_joints, m.n_frames) == (120.0, 53, 2539)
    assert m.provenance["up_axis"] == "y"
    assert 1.4 < np.percentile(np.ptp(m.positions[..., 2], axis=1), 95) < 2.0


def test_fetch_reports_progress_per_file(tmp_path):
    root = _fake_tree(tmp_path / "sys", gzip_c3d=True)
    lines: list[str] = []
    fetch_motions(tmp_path / "cache", system_root=root, progress=lines.append)
    assert [line.split(":")[0] for line in lines] == [f.name for f in MOTION_FILES]
    assert all("copied from the installed package" in line for line in lines)
    lines.clear()
    fetch_motions(tmp_path / "cache", system_root=root, progress=lines.append)
    assert lines == [f"{f.name}: already cached" for f in MOTION_FILES]


def test_cache_dir_honours_env(tmp_path, monkeypatch):
    monkeypatch.setenv("GTT_CACHE", str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"
    monkeypatch.delenv("GTT_CACHE")
    assert cache_dir() == Path.home() / ".cache" / "gtt" / "motions"


@pytest.mark.mocap
def test_real_fetch_then_show(tmp_path, monkeypatch):
    """The real thing: copies from /usr/share when installed, else apt-get download (needs the Debian mirror)."""
    installed = all(
        (Path("/") / f.member).is_file() or (Path("/") / (f.member + ".gz")).is_file() for f in MOTION_FILES
    )
    if not installed and shutil.which("apt-get") is None:
        pytest.skip("neither the Debian packages nor apt-get are available")
    monkeypatch.setenv("GTT_CACHE", str(tmp_path / "cache"))
    r = CliRunner().invoke(main, ["motions", "fetch"])
    if r.exit_code == 1 and "apt-get download" in r.output and "failed" in r.output:
        pytest.skip(f"no Debian mirror reachable: {r.output.strip().splitlines()[-1]}")
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["motions", "show", "01_01.bvh"])
    assert r.exit_code == 0, r.output
    assert "frames: 2752" in r.output and "joints: 31" in r.output and "fps: 120" in r.output
    r = CliRunner().invoke(main, ["motions", "list"])
    assert "Boxing_Toes.bvh" in r.output and " 3070 " in r.output
