"""Item D16 of issue 29 (data parts): ``--split`` on a shard file, and datasets and training runs in one folder.

A shard file holds one split, so ``--split`` was silently ignored for it: ``reconstruct train/shard.h5
--split val`` read a train sample. And ``gttnet train --out`` onto a dataset folder (or ``gttdata generate
--out`` onto a run folder) wrote one output into the other's files.
"""

from __future__ import annotations

import shutil

import pytest
from click.testing import CliRunner

from gttdata.cli import main as gttdata_main
from gttnet.cli import main as gttnet_main
from gttnet.train.rundir import RUN_FILES
from tests.reliability.conftest import TINY, one_line_error

SHARD = "train/shard-00000.h5"

COMMANDS = [
    (gttnet_main, ["reconstruct", "{shard}", "--method", "pseudo"]),
    (gttnet_main, ["sync", "{shard}"]),
    (gttnet_main, ["segment", "{shard}", "--out", "{tmp}/seg"]),
    (gttnet_main, ["export-json", "{shard}", "--out", "{tmp}/x.json"]),
    (gttdata_main, ["export", "{shard}", "--out", "{tmp}/rec"]),
    (gttdata_main, ["preview", "{shard}", "--out", "{tmp}/pv", "--no-3d"]),
]


@pytest.mark.parametrize("main, args", COMMANDS, ids=[a[0] for _, a in COMMANDS])
def test_a_split_that_contradicts_the_shard_is_refused(tiny_data, tmp_path, main, args):
    """Every command that takes a shard and ``--split``: one line naming the shard and both splits."""
    argv = [a.format(shard=tiny_data / SHARD, tmp=tmp_path) for a in args]
    line = one_line_error(CliRunner().invoke(main, [*argv, "--split", "val"]))
    assert str(tiny_data / SHARD) in line and "'val'" in line and "'train'" in line
    assert not any(tmp_path.iterdir()), "refused before writing anything"


def test_the_shard_own_split_and_the_default_are_accepted(tiny_data):
    shard = str(tiny_data / SHARD)
    for extra in (["--split", "train"], []):  # the default (test) does not apply to a shard file
        res = CliRunner().invoke(gttnet_main, ["reconstruct", shard, "--method", "pseudo", "--quiet", *extra])
        assert res.exit_code == 0, res.output


def test_split_still_selects_within_a_dataset_folder(tiny_data):
    res = CliRunner().invoke(
        gttnet_main, ["reconstruct", str(tiny_data), "--split", "val", "--method", "pseudo", "--json"]
    )
    assert res.exit_code == 0, res.output


def test_train_refuses_a_dataset_folder(tiny_data, tmp_path):
    """Even with ``--overwrite``: the dataset is not a run to replace. Its files are untouched."""
    root = tmp_path / "d"
    shutil.copytree(tiny_data, root)
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file() and p.name != ".gtt.lock"}
    for extra in ([], ["--overwrite"], ["--resume"]):
        argv = ["train", "recipes/gttnet/tiny.yaml", "--out", str(root), "--device", "cpu", *extra]
        line = one_line_error(CliRunner().invoke(gttnet_main, argv))
        assert str(root) in line and "gttdata dataset (manifest.json and 3 shard files)" in line
    after = {p: p.read_bytes() for p in root.rglob("*") if p.is_file() and p.name != ".gtt.lock"}
    assert after == before
    assert CliRunner().invoke(gttdata_main, ["verify", str(root)]).exit_code == 0


def test_generate_refuses_a_training_run_folder(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.pt").write_bytes(b"a model")
    (run / "log.jsonl").write_text('{"kind": "meta"}\n')
    for extra in ([], ["--overwrite"], ["--resume"]):
        res = CliRunner().invoke(gttdata_main, ["generate", TINY, "--out", str(run), "--no-progress", *extra])
        line = one_line_error(res)
        assert str(run) in line and "gttnet training run (model.pt, log.jsonl)" in line
    assert sorted(p.name for p in run.iterdir()) == ["log.jsonl", "model.pt"], "nothing written, no lock file"


def test_training_run_markers_are_run_files():
    """Gttdata cannot import gttnet: its list of what marks a run folder must stay within gttnet's."""
    from gttdata.fileio import TRAINING_RUN_MARKERS

    assert set(TRAINING_RUN_MARKERS) <= set(RUN_FILES)
