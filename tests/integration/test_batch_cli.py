"""``gttnet batch``: every trial of a Pose2Sim session, jobs, parts, resume, and a failing trial."""

from __future__ import annotations

import json
import shutil

import pytest
from click.testing import CliRunner

from gttnet.batch import list_trials, parse_part, summary_table
from gttnet.cli import main
from tests.integration._pose2sim_trial import write_session

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A session with three trials sharing one calibration (P01/T01, P01/T02, P02/T01)."""
    root = tmp_path_factory.mktemp("batch") / "Session"
    trial, _, _ = write_session(root)
    shutil.copytree(trial, root / "P01" / "T02")
    shutil.copytree(trial, root / "P02" / "T01")
    return root


def test_trials_are_listed_in_natural_order_and_parts_split_them(session):
    names = [str(t.relative_to(session)) for t in list_trials(session)]
    assert names == ["P01/T01", "P01/T02", "P02/T01"]
    assert parse_part("2/3") == (2, 3)
    for bad in ("0/2", "3/2", "x", "1-2"):
        with pytest.raises(ValueError, match="--part"):
            parse_part(bad)


@pytest.mark.slow
def test_batch_runs_every_trial_then_resumes_and_splits(session, tmp_path):
    out = tmp_path / "out"
    res = CliRunner().invoke(
        main, ["batch", str(session), "--out", str(out), "--jobs", "2", "--json", "--no-progress"]
    )
    assert res.exit_code == 0, res.output
    rows = json.loads(res.stdout.strip().splitlines()[-1])["trials"]
    assert [r["trial"] for r in rows] == ["P01/T01", "P01/T02", "P02/T01"]
    assert all(r["status"] == "ok" for r in rows)
    for r in rows:
        trc = out / r["trial"] / "result.trc"
        assert trc.is_file() and (out / r["trial"] / "summary.json").is_file()
        assert "DataRate" in trc.read_text()[:2000]
    # The three trials hold the same detections: the same motion comes out of each.
    assert len({(out / r["trial"] / "result.trc").read_text() for r in rows}) == 1
    again = CliRunner().invoke(main, ["batch", str(session), "--out", str(out), "--json", "--no-progress"])
    assert [r["status"] for r in json.loads(again.stdout.strip().splitlines()[-1])["trials"]] == [
        "skipped"
    ] * 3
    part = CliRunner().invoke(
        main,
        ["batch", str(session), "--out", str(tmp_path / "p"), "--part", "2/2", "--json", "--no-progress"],
    )
    assert [r["trial"] for r in json.loads(part.stdout.strip().splitlines()[-1])["trials"]] == ["P01/T02"]


@pytest.mark.slow
def test_a_failing_trial_is_one_line_and_the_others_run(session, tmp_path):
    broken = tmp_path / "S"
    shutil.copytree(session, broken)
    for f in (broken / "P01" / "T02" / "pose").rglob("*.json"):
        f.write_text("{not json")
    res = CliRunner().invoke(main, ["batch", str(broken), "--out", str(tmp_path / "o"), "--no-progress"])
    assert res.exit_code == 1 and "1 of 3 trials failed" in res.output
    table = res.stdout
    assert "P01/T01" in table and "failed: Error:" in table and "not valid JSON" in table
    assert "Traceback" not in res.output
    ok = [ln for ln in table.splitlines() if ln.startswith(("P01/T01", "P02/T01"))]
    assert len(ok) == 2 and all(" ok " in ln for ln in ok)


def test_options_after_the_double_dash_reach_every_trial(session, tmp_path):
    out = tmp_path / "o"
    res = CliRunner().invoke(
        main,
        [
            "batch",
            str(session),
            "--out",
            str(out),
            "--part",
            "1/3",
            "--format",
            ".csv",
            "--no-progress",
            "--",
            "--method",
            "dloe",
        ],
    )
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "P01" / "T01" / "summary.json").read_text())
    assert summary["method"] == "dloe" and (out / "P01" / "T01" / "result.csv").is_file()


def test_a_failing_trial_is_reported_in_the_table(session, tmp_path):
    broken = tmp_path / "S"
    shutil.copytree(session, broken)
    for f in (broken / "P01" / "T02" / "pose").rglob("*.json"):
        f.write_text("{not json")
    res = CliRunner().invoke(
        main, ["batch", str(broken), "--out", str(tmp_path / "o"), "--part", "2/3", "--no-progress"]
    )
    assert res.exit_code == 1 and "1 of 1 trials failed" in res.output and "Traceback" not in res.output
    assert "P01/T02" in res.stdout and "not valid JSON" in res.stdout


def test_no_trial_is_one_line(tmp_path):
    res = CliRunner().invoke(main, ["batch", str(tmp_path), "--out", str(tmp_path / "o")])
    assert (
        res.exit_code == 1 and "no trial folder" in res.output and len(res.output.strip().splitlines()) == 1
    )


def test_summary_table_reads_the_quality_estimate():
    from gttnet.batch import TrialResult

    r = TrialResult("P/T", "ok", "x", summary={"n_images": 10, "quality": {"expected_error_mm": 12.345}})
    assert "12.3" in summary_table([r])
