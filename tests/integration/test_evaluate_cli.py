"""End-to-end ``gttnet evaluate``, ``gttnet segment`` and ``gttnet reconstruct --subjects 2`` runs."""

from __future__ import annotations

import json

import pytest
import yaml
from click.testing import CliRunner

from gttnet.cli import main

pytestmark = pytest.mark.integration


def _run(*args):
    return CliRunner().invoke(main, [*map(str, args)])


def test_evaluate_smoke_recipe_and_resume(tmp_path):
    args = [
        "evaluate",
        "recipes/gttnet/eval_smoke.yaml",
        "data.n_sequences=1",
        "sweeps=[{name: noise, variable: capture.sigma_px, values: [0, 3]}]",
        "methods=[pseudo, hpf, gttnet]",
        "--out",
        tmp_path / "run",
        "--quiet",
    ]
    res = _run(*args)
    assert res.exit_code == 0, res.output
    assert "## noise" in res.output and "## Notes" in res.output
    for name in ("errors.csv", "summary.md", "sweep_noise.png", "recipe.json"):
        assert (tmp_path / "run" / name).is_file()
    n_rows = len((tmp_path / "run" / "errors.csv").read_text().splitlines())
    assert n_rows == 1 + 2 * 3 * 3
    refused = _run(*args)  # docs/CLI.md: an existing run is neither continued nor replaced silently
    assert refused.exit_code == 1 and "pass --resume to continue it or --overwrite" in refused.output
    again = _run(*args, "--resume")
    assert again.exit_code == 0, again.output
    assert len((tmp_path / "run" / "errors.csv").read_text().splitlines()) == n_rows
    (tmp_path / "run" / "errors.csv").write_text("job_id\n")  # a damaged run: --overwrite starts again
    fresh = _run(*args, "--overwrite")
    assert fresh.exit_code == 0, fresh.output
    assert len((tmp_path / "run" / "errors.csv").read_text().splitlines()) == n_rows


def test_evaluate_json_summarises_every_cell(tmp_path):
    args = ["evaluate", "recipes/gttnet/eval_smoke.yaml", "data.n_sequences=2", "sweeps=[]"]
    res = _run(*args, "methods=[pseudo, dloe]", "sequencing=[none]", "--out", tmp_path / "run", "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.output)
    assert report["run_dir"] == str(tmp_path / "run")
    cells = {c["method"]: c for c in report["cells"]}
    assert set(cells) == {"pseudo", "dloe"}
    for c in cells.values():
        assert c["sequencing"] == "none" and c["n_ok"] == 2 and c["n_skipped"] == 0
        assert c["mpjpe_mm_mean"] > 0 and 0 <= c["kendall_tau_mean"] <= 1
    rows = [r.split(",") for r in (tmp_path / "run" / "errors.csv").read_text().splitlines()[1:]]
    dloe = [float(r[8]) for r in rows if r[5] == "dloe"]
    assert cells["dloe"]["mpjpe_mm_mean"] == pytest.approx(sum(dloe) / len(dloe))


def test_evaluate_bad_key_is_one_line(tmp_path):
    res = _run("evaluate", "recipes/gttnet/eval_smoke.yaml", "data.bogus=1", "--out", tmp_path / "x")
    assert res.exit_code != 0
    assert "data.bogus: unknown key" in res.output
    assert "Traceback" not in res.output and len(res.output.strip().splitlines()) == 1


def test_evaluate_runtime_flag(tmp_path):
    res = _run(
        "evaluate",
        "recipes/gttnet/eval_smoke.yaml",
        "runtime={lengths: [30], methods: [pseudo, dloe], generate: recipes/gttdata/tiny.yaml}",
        "--runtime",
        "--out",
        tmp_path / "rt",
        "--quiet",
    )
    assert res.exit_code == 0, res.output
    assert "| images |" in res.output
    assert (tmp_path / "rt" / "runtime" / "runtime.png").is_file()


def test_segment_cli(tmp_path):
    data = yaml.safe_load(open("recipes/gttdata/events.yaml"))
    data["rig"]["n_cameras"] = 4
    data["capture"].update({"fps_hz": 10.0, "window_s": 1.0, "sigma_px": 0.0})
    data["scene"].update({"n_events": 2, "event_gap_s": 1.0})
    # Well-separated events by construction: a standing gesture and a run have no pose in common
    # (two random kinds can be a run and a jog, which no order-free affinity can tell apart).
    for split in data["splits"]:
        for source in split["sources"]:
            source["kinds"] = ["gesture", "run"]
    recipe = tmp_path / "events_tiny.yaml"
    recipe.write_text(yaml.safe_dump(data))
    res = _run("segment", recipe, "--sample", 0, "--out", tmp_path / "seg")
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "seg" / "segmentation.json").read_text())
    assert report["n_events"] == 2 and report["ari"] == 1.0
    lines = (tmp_path / "seg" / "labels.csv").read_text().splitlines()
    assert lines[0].startswith("image,stored_index,camera,event,order_in_event") and len(lines) == 81
    assert (tmp_path / "seg" / "affinity.png").stat().st_size > 1000
    again = _run("segment", recipe, "--sample", 0, "--out", tmp_path / "seg")  # refused before any work
    assert again.exit_code == 1 and "already holds a segmentation; pass --overwrite" in again.output
    assert json.loads((tmp_path / "seg" / "segmentation.json").read_text()) == report
    res = _run("segment", recipe, "--sample", 0, "--out", tmp_path / "seg", "--overwrite", "--json")
    assert res.exit_code == 0, res.output
    printed = json.loads(res.output)  # the report again (its timing aside), and where it went
    assert printed.pop("out") == str(tmp_path / "seg") and printed.pop("seconds") > 0
    assert printed == {k: v for k, v in report.items() if k != "seconds"}


def test_reconstruct_two_subjects(tmp_path):
    from gttdata.cli import main as gttdata_main

    gen = CliRunner().invoke(
        gttdata_main,
        [
            "generate",
            "recipes/gttdata/multi_subject.yaml",
            "splits.train.n_samples=1",
            "splits.val.n_samples=1",
            "splits.test.n_samples=1",
            "capture.window_s=0.6",
            "capture.sigma_px=0",
            "--out",
            str(tmp_path / "ms"),
            "--no-progress",
        ],
    )
    assert gen.exit_code == 0, gen.output
    res = _run(
        "reconstruct",
        tmp_path / "ms",
        "--subjects",
        2,  # the default method: auto means DLOE here (the clustering needs its affinity)
        "--json",
        "--out",
        tmp_path / "r.h5",
    )
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output.strip().splitlines()[-1])
    assert summary["n_subjects"] == 2 and summary["clustering_accuracy"] >= 0.95
    assert len(summary["mpjpe_mm_per_subject"]) == 2
    assert (tmp_path / "r.h5").is_file()


def test_evaluate_from_outside_the_repository(tmp_path, monkeypatch):
    """Paths inside a recipe resolve against its folder; a recipe error leaves no run folder behind."""
    from pathlib import Path

    recipe = Path(__file__).resolve().parents[2] / "recipes" / "gttnet" / "eval_smoke.yaml"
    monkeypatch.chdir(tmp_path)
    common = [recipe, "data.n_sequences=1", "sequencing=[full]", "--quiet", "--no-plots"]
    r = _run("evaluate", *common, "methods=[pseudo]", "--out", "ok")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "ok" / "errors.csv").is_file()
    r = _run("evaluate", *common, "methods=[nope]", "--out", "bad")
    assert r.exit_code == 1 and "unknown method 'nope'" in r.output
    assert not (tmp_path / "bad").exists()
