"""``gttnet sync`` through click's CliRunner: JSON report, clocks file, frame-times CSV, one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from gttnet.cli import main
from gttnet.sync import Clocks
from tests.gttnet.test_sync import _capture


@pytest.fixture(scope="module")
def shard(tmp_path_factory):
    writer = pytest.importorskip("gttdata.shards.writer")
    out = tmp_path_factory.mktemp("sync_shard")
    with writer.ShardWriter(out, split="test") as w:
        w.write(_capture())
    return sorted(out.glob("*.h5"))[0]


def test_sync_json_and_clocks_file(tmp_path, shard):
    out = tmp_path / "clocks.json"
    r = CliRunner().invoke(main, ["sync", str(shard), "--fps", "25,30,60", "--out", str(out), "--json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert [c["camera"] for c in rep["cameras"]] == [0, 1, 2]
    assert [c["rate_hz"] for c in rep["cameras"]] == [25.0, 30.0, 60.0]
    assert max(abs(e) for e in rep["offset_error_frames"]) < 0.1
    clocks = Clocks.load(out)
    np.testing.assert_allclose(clocks.offset_s, [c["offset_s"] for c in rep["cameras"]])
    # Nothing is overwritten without --overwrite.
    again = CliRunner().invoke(main, ["sync", str(shard), "--out", str(out)])
    assert again.exit_code == 1 and "--overwrite" in again.output and "Traceback" not in again.output
    human = CliRunner().invoke(
        main, ["sync", str(shard), "--fps", "0=25,1=30,2=60", "--out", str(out), "--overwrite"]
    )
    assert human.exit_code == 0 and "offset std ms" in human.output


def test_sync_frame_times_csv(tmp_path, shard):
    from gttnet.io import load_input

    obs = load_input(shard, sequencing="partial").observations
    rate = np.array([25.0, 30.0, 60.0])
    csv = tmp_path / "pts.csv"
    lines = ["camera,frame,time_s"] + [
        f"{c},{k},{k / rate[c] + 10.0 * c}" for c, k in zip(obs.cam_id, obs.stream_index, strict=True)
    ]  # each camera's clock reads 10 s more than the last: offsets absorb it
    csv.write_text("\n".join(lines) + "\n")
    r = CliRunner().invoke(
        main,
        [
            "sync",
            str(shard),
            "--frame-times",
            str(csv),
            "--fps",
            "25,30,60",
            "--out",
            str(tmp_path / "c.json"),
            "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    assert max(abs(e) for e in json.loads(r.output)["offset_error_frames"]) < 0.1
    csv.write_text("camera,frame,time_s\n0,0,abc\n")
    bad = CliRunner().invoke(
        main, ["sync", str(shard), "--frame-times", str(csv), "--out", str(tmp_path / "d.json")]
    )
    assert bad.exit_code == 1 and "line 2" in bad.output and "Traceback" not in bad.output


def test_sync_bad_fps_is_a_usage_error(tmp_path, shard):
    r = CliRunner().invoke(main, ["sync", str(shard), "--fps", "fast", "--out", str(tmp_path / "c.json")])
    assert r.exit_code == 2 and "--fps" in r.output


def test_reconstruct_auto_runs_sync_on_partial_input(tmp_path):
    writer = pytest.importorskip("gttdata.shards.writer")
    from tests.gttnet.test_sync import _capture

    with writer.ShardWriter(tmp_path / "s", split="test") as w:
        w.write(_capture((0.0, 1.3, 0.4), (30.0, 30.0, 30.0), end_s=2.5))
    shard = sorted((tmp_path / "s").glob("*.h5"))[0]
    r = CliRunner().invoke(main, ["reconstruct", str(shard), "--sequencing", "partial", "--json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output.strip().splitlines()[-1])
    assert rep["method"] == "sync" and rep["requested_method"] == "auto"
    offs = rep["clock_offsets_s"]
    np.testing.assert_allclose([offs["0"], offs["1"], offs["2"]], [0.0, 1.3, 0.4], atol=0.1 / 30)
    assert rep["order_kendall_tau"] > 0.99


def test_sync_reads_a_recordings_project_file(tmp_path, shard):
    from gttdata.cli import main as gttdata_main

    res = CliRunner().invoke(gttdata_main, ["export", str(shard), "--out", str(tmp_path / "rec")])
    assert res.exit_code == 0, res.output
    r = CliRunner().invoke(
        main, ["sync", str(tmp_path / "rec" / "project.toml"), "--out", str(tmp_path / "c.json"), "--json"]
    )
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output.strip().splitlines()[-1])
    assert [c["name"] for c in rep["cameras"]] == ["cam_0", "cam_1", "cam_2"]
    ref = CliRunner().invoke(
        main, ["sync", str(shard), "--fps", "25,30,60", "--out", str(tmp_path / "d.json"), "--json"]
    )
    want = [c["offset_s"] for c in json.loads(ref.output)["cameras"]]
    np.testing.assert_allclose([c["offset_s"] for c in rep["cameras"]], want, atol=0.05 / 60)
