"""Issue 29 D4, D5, D10: outputs never vanish and nothing is written or deleted outside its folder."""

from __future__ import annotations

import pytest
import torch
from click.testing import CliRunner

from tests.reliability.conftest import TINY, one_line_error

# --- D10: a full disk while the training item cache is written ----------------------------------------


def _dataset(cache_dir):
    from gttdata.recipe import load_recipe
    from gttnet.data import RecipeSource, SequenceDataset

    src = RecipeSource(load_recipe(TINY), "train")
    return SequenceDataset(src, k=6, sequencing={"none": 1.0}, cache="disk", cache_dir=cache_dir)


def test_item_cache_on_a_full_disk_warns_once_and_leaves_no_tmp(small_fs, caplog):
    """Training goes on from memory; one warning line names the file; no ``.tmp`` is left behind."""
    (small_fs / "filler").write_bytes(b"\0" * (2 * 1024 * 1024 - 8 * 1024))
    cache = small_fs / "item_cache"
    ds = _dataset(cache)
    with caplog.at_level("WARNING", logger="gttnet.data"):
        items = [ds[(i, 0, None)] for i in range(3)]
    assert all(torch.isfinite(it.inputs.x_init).all() for it in items)
    warned = [r.getMessage() for r in caplog.records if r.name == "gttnet.data"]
    assert len(warned) == 1 and "no space left on device" in warned[0] and "\n" not in warned[0], warned
    assert str(cache) in warned[0]
    leftovers = [p.name for p in small_fs.rglob("*") if p.name.endswith(".tmp")]
    assert leftovers == []


def test_item_cache_write_error_anywhere(tmp_path, monkeypatch, caplog):
    """Same contract without a tmpfs: the write fails with ENOSPC inside ``atomic_write``."""
    import errno
    import os

    real_fsync = os.fsync

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    ds = _dataset(tmp_path / "item_cache")
    monkeypatch.setattr(os, "fsync", full)
    with caplog.at_level("WARNING", logger="gttnet.data"):
        item = ds[(0, 0, None)]
        ds[(1, 0, None)]
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert item.inputs.x_init.shape[0] > 0
    warned = [r.getMessage() for r in caplog.records if r.name == "gttnet.data"]
    assert len(warned) == 1 and "cannot write: no space left on device" in warned[0], warned
    assert list((tmp_path / "item_cache").iterdir()) == []  # neither an item nor a .tmp


# --- D5: split names are folder names ------------------------------------------------------------------


@pytest.mark.parametrize("name", [".", "..", ".hidden", "a/b", "", "train\n", "../x"])
def test_split_name_that_is_not_a_plain_folder_name_is_refused(tmp_path, name):
    """``.``/``..`` would put (and delete) shard files outside --out: refused before anything is written."""
    from gttdata.cli import main

    box = tmp_path / "box"
    out = box / "data"
    box.mkdir()
    (box / "keep.txt").write_text("mine")
    res = CliRunner().invoke(
        main, ["generate", TINY, f"splits.0.name={name!r}", "--out", str(out), "--no-progress"]
    )
    line = one_line_error(res)
    assert "splits" in line and "name" in line and "not starting with '.'" in line, line
    assert sorted(p.name for p in box.iterdir()) == ["keep.txt"]


def test_split_names_with_dots_inside_still_pass():
    from gttdata.recipe import load_recipe

    recipe = load_recipe(TINY, ["splits.0.name=v1.2-a_b"])
    assert recipe.splits[0].name == "v1.2-a_b"


# --- D4: export --overwrite deletes only an earlier export ---------------------------------------------


def _export(source, out, *extra):
    from gttdata.cli import main

    return CliRunner().invoke(main, ["export", str(source), "--split", "test", "--out", str(out), *extra])


def _tree(root):
    return sorted((str(p.relative_to(root)), p.stat().st_size) for p in root.rglob("*") if p.is_file())


@pytest.mark.parametrize("where", ["itself", "parent"])
def test_export_overwrite_never_deletes_the_dataset(tmp_path, tiny_data, where):
    """``--out`` equal to, or holding, the dataset being exported: one line, every shard kept."""
    import shutil

    data = tmp_path / "box" / "data"
    shutil.copytree(tiny_data, data)
    before = _tree(data)
    out = data if where == "itself" else data.parent
    line = one_line_error(_export(data, out, "--overwrite"))
    assert "data being exported" in line and str(out) in line
    assert _tree(data) == before


def test_export_overwrite_refuses_a_folder_that_is_not_an_export(tmp_path, tiny_data):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("do not lose me")
    (out / "project.toml").write_text('source = "my own project"\ncameras = []\n')
    line = one_line_error(_export(tiny_data, out, "--overwrite"))
    assert "earlier gttdata export" in line and "nothing deleted" in line
    assert (out / "notes.txt").read_text() == "do not lose me"
    assert (out / "project.toml").read_text().startswith('source = "my own project"')


def test_export_overwrite_replaces_only_what_the_export_wrote(tmp_path, tiny_data):
    out = tmp_path / "rec"
    assert _export(tiny_data, out).exit_code == 0
    assert (out / "cam_0").is_dir()
    (out / "notes.txt").write_text("mine")
    (out / "cam_0" / "README").write_text("mine too")
    res = _export(tiny_data, out, "--overwrite", "--format", "dlc")
    assert res.exit_code == 0, res.output
    assert (out / "notes.txt").read_text() == "mine" and (out / "cam_0" / "README").read_text() == "mine too"
    assert not list((out / "cam_0").glob("*_keypoints.json"))  # the earlier OpenPose files went
    assert (out / "cam_0.csv").is_file() and (out / "project.toml").is_file()


def test_export_refuses_project_names_outside_the_folder(tmp_path, tiny_data):
    out = tmp_path / "rec"
    assert _export(tiny_data, out).exit_code == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("keep")
    text = (
        (out / "project.toml")
        .read_text()
        .replace('timestamps = "cam_0_timestamps.csv"', 'timestamps = "../victim.txt"')
    )
    (out / "project.toml").write_text(text)
    line = one_line_error(_export(tiny_data, out, "--overwrite"))
    assert "../victim.txt" in line and victim.read_text() == "keep"
