"""Evaluation harness: recipes, rows, summary, plots, skip notes, resume, the GTT-Net Q option and runtime."""

from __future__ import annotations

import glob

import numpy as np
import pytest

from gttnet.evaluate import run as run_mod
from gttnet.evaluate.recipe import EvalRecipeError, RuntimeSpec, load_eval_recipe, parse_eval_recipe
from gttnet.evaluate.run import CSV_FIELDS, evaluate, plan_jobs, read_rows
from gttnet.evaluate.summary import error_bar, group_stats, mean_interval

RECIPES = sorted(glob.glob("recipes/gttnet/eval_*.yaml") + glob.glob("recipes/gttnet/ablation_*.yaml"))


def _tiny(tmp_path, **extra) -> dict:
    data = {
        "name": "t",
        "output_dir": str(tmp_path / "run"),
        "data": {"generate": "recipes/gttdata/tiny.yaml", "split": "test", "n_sequences": 1},
        "sweeps": [{"name": "noise", "variable": "capture.sigma_px", "values": [0, 2]}],
        "sequencing": ["none", "full"],
        "methods": [
            "pseudo",
            "hpf",
            {"name": "gttnet_missing", "method": "gttnet", "options": {"model": str(tmp_path / "no.pt")}},
        ],
    }
    data.update(extra)
    return data


@pytest.mark.parametrize("path", RECIPES)
def test_every_eval_recipe_parses_and_plans(path):
    recipe = load_eval_recipe(path)
    jobs = plan_jobs(recipe)
    assert jobs and len({j.job_id for j in jobs}) == len(jobs)
    assert recipe.methods


def test_recipe_lists_are_found():
    names = {p.split("/")[-1] for p in RECIPES}
    assert {"eval_smoke.yaml", "eval_paper.yaml", "ablation_sparsity.yaml"} <= names
    assert {"ablation_cascade.yaml", "ablation_pointnet.yaml"} <= names


def test_paper_recipe_has_the_paper_sweeps():
    r = load_eval_recipe("recipes/gttnet/eval_paper.yaml")
    sweeps = {s.name: [v.value for v in s.values] for s in r.sweeps}
    assert sweeps["noise"] == [0, 1, 2, 3, 4, 5]
    assert sweeps["frame_rate"] == [7.5, 15, 30]
    assert sweeps["missing"] == pytest.approx([0, 0.1, 0.2, 0.3, 0.4, 0.5])
    assert r.sequencing == ["none", "partial", "full"]


def test_unknown_key_is_a_one_line_error(tmp_path):
    with pytest.raises(EvalRecipeError, match=r"data\.n_seq: unknown key") as exc:
        parse_eval_recipe(_tiny(tmp_path), ["data.n_seq=3"])
    assert "\n" not in str(exc.value)
    with pytest.raises(EvalRecipeError, match="error_bars"):
        parse_eval_recipe(_tiny(tmp_path, error_bars="sem"))


def test_overrides_reach_the_recipe(tmp_path):
    r = parse_eval_recipe(_tiny(tmp_path), ["data.n_sequences=2", "sweeps.0.values=[1]", "methods=[dloe]"])
    assert r.data.n_sequences == 2 and r.sweeps[0].values[0].value == 1.0
    assert [m.name for m in r.methods] == ["dloe"]


def test_unknown_method_fails_before_work(tmp_path):
    with pytest.raises(EvalRecipeError, match="unknown method"):
        plan_jobs(parse_eval_recipe(_tiny(tmp_path, methods=["nope"])))


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ev")
    recipe = parse_eval_recipe(_tiny(tmp))
    return recipe, evaluate(recipe, progress=False)


def test_tiny_run_rows(tiny_run):
    recipe, out = tiny_run
    rows = read_rows(out / "errors.csv")
    assert len(rows) == 2 * 2 * 3  # values x sequencing x methods (1 sequence)
    assert set(rows[0]) == set(CSV_FIELDS)
    ok = [r for r in rows if r["status"] == "ok"]
    assert {(r["sequencing"], r["method"]) for r in ok} == {
        ("none", "pseudo"),
        ("full", "pseudo"),
        ("full", "hpf"),
    }
    for r in ok:
        assert 0.0 < float(r["mpjpe_mm"]) < 200.0 and 0.0 <= float(r["kendall_tau"]) <= 1.0
    # noise hurts pseudo-triangulation
    e = {
        r["value"]: float(r["mpjpe_mm"]) for r in ok if r["method"] == "pseudo" and r["sequencing"] == "full"
    }
    assert e["2"] > e["0"]


def test_tiny_run_skip_notes(tiny_run):
    _, out = tiny_run
    rows = read_rows(out / "errors.csv")
    skipped = [r for r in rows if r["status"] == "skipped"]
    hpf_none = [r for r in skipped if r["method"] == "hpf"]
    assert hpf_none and all("global image order" in r["note"] for r in hpf_none)
    model = [r for r in skipped if r["method"] == "gttnet_missing"]
    assert len(model) == 4 and all("no.pt" in r["note"] for r in model)
    text = (out / "summary.md").read_text()
    assert "## Notes" in text and "gttnet_missing" in text


def test_tiny_run_summary_and_plots(tiny_run):
    _, out = tiny_run
    text = (out / "summary.md").read_text()
    assert "## noise" in text and "| full | pseudo |" in text and "skip" in text
    assert "95% bootstrap interval" in text
    assert (out / "sweep_noise.png").stat().st_size > 1000
    assert (out / "recipe.json").is_file()


def test_group_stats_and_error_bars():
    rows = [
        {
            "condition": "c",
            "value": "1",
            "sequencing": "none",
            "method": "m",
            "status": "ok",
            "mpjpe_mm": str(v),
            "kendall_tau": "1",
            "seconds": "0.1",
            "note": "",
        }
        for v in (1.0, 2.0, 3.0)
    ]
    (g,) = group_stats(rows)
    assert g.n == 3 and g.mean_mm == pytest.approx(2.0) and g.median_mm == pytest.approx(2.0)
    assert g.std_mm == pytest.approx(1.0)
    assert error_bar(np.array([1.0, 2.0, 3.0]), "ci95") == pytest.approx(4.302653 / np.sqrt(3), rel=1e-5)
    assert error_bar(np.array([1.0, 2.0, 3.0]), "std") == pytest.approx(1.0)


def test_mean_interval_never_reaches_below_zero():
    """With n = 2 a t-interval once drew bars to -40 mm; the bootstrap interval stays within the data's range."""
    v = np.array([2.0, 60.0])
    assert 31.0 - error_bar(v, "ci95") < -300  # the old bar
    lo, hi = mean_interval(v, "ci95")
    assert 2.0 <= lo <= 31.0 <= hi <= 60.0
    assert mean_interval(v, "ci95") == (lo, hi)  # fixed seed: plots are reproducible
    assert mean_interval(v, "std")[0] == 0.0
    w = np.random.default_rng(0).gamma(2.0, 5.0, size=200)
    lo, hi = mean_interval(w, "ci95")
    half = error_bar(w, "ci95")  # large n: the bootstrap agrees with the t-interval
    assert lo == pytest.approx(w.mean() - half, rel=0.05) and hi == pytest.approx(w.mean() + half, rel=0.05)
    assert mean_interval(np.array([4.0]), "ci95") == (4.0, 4.0)


def test_resume_skips_done_jobs(tmp_path, monkeypatch):
    recipe = parse_eval_recipe(_tiny(tmp_path, methods=["pseudo"], sequencing=["full"]))
    evaluate(recipe, progress=False, plots=False)
    csv_path = tmp_path / "run" / "errors.csv"
    assert len(read_rows(csv_path)) == 2
    calls = []
    real = run_mod.run_job
    monkeypatch.setattr(
        run_mod, "run_job", lambda r, j, todo=None: calls.append((j.job_id, sorted(todo))) or real(r, j, todo)
    )
    evaluate(recipe, progress=False, plots=False)
    assert calls == []
    lines = csv_path.read_text().splitlines()
    csv_path.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:10])  # a kill mid-row of the last job
    evaluate(recipe, progress=False, plots=False)
    assert calls == [(lines[-1].split(",")[0], [("full", "pseudo")])]
    assert len(read_rows(csv_path)) == 2 and csv_path.read_text().count("\n") == 3
    calls.clear()
    wider = parse_eval_recipe(_tiny(tmp_path, methods=["pseudo", "hpf"], sequencing=["full"]))
    evaluate(wider, progress=False, plots=False)  # a method added to a finished run: only it runs
    assert [todo for _, todo in calls] == [[("full", "hpf")]] * 2
    assert len(read_rows(csv_path)) == 4
    with pytest.raises(EvalRecipeError, match="exists"):
        evaluate(recipe, progress=False, resume=False)


def test_gttnet_top_q_option_leaves_the_cached_model_alone(tmp_path):
    from gttdata.capture.views import make_view
    from gttdata.generate_plan import build_sample
    from gttdata.recipe import load_recipe
    from gttnet.evaluate.recipe import MethodEntry
    from gttnet.model.inference import save_model
    from gttnet.model.network import build_model

    path = save_model(tmp_path / "m.pt", build_model("gttnet_tiny"))
    obs, _ = make_view(build_sample(load_recipe("recipes/gttdata/tiny.yaml"), "test", 0)[0], "none")
    recs = {
        q: run_mod.run_method(obs, MethodEntry(method="gttnet", options={"model": str(path), "top_q": q}))
        for q in (1, 3)
    }
    nnz = {q: int((r.affinity > 0).sum()) for q, r in recs.items()}
    assert nnz[1] < nnz[3] <= 3 * obs.n_images * 2
    assert recs[3].info["top_q"] == 3 and recs[3].order is not None
    from gttnet.model.inference import cached_reconstructor

    assert cached_reconstructor(str(path)).model.affinity.top_q == 2


def test_runtime_study_tiny(tmp_path):
    from gttnet.evaluate.runtime import run_runtime

    spec = RuntimeSpec(lengths=[30, 45], methods=["pseudo", "gttnet"], generate="recipes/gttdata/tiny.yaml")
    res = run_runtime(spec, tmp_path / "rt")
    assert abs(res.n_images[0] - 30) <= 3 and abs(res.n_images[1] - 45) <= 3
    assert all(s > 0 for v in res.seconds.values() for s in v)
    assert "untrained" in res.notes["gttnet"] or "trained" in res.notes["gttnet"]
    assert (tmp_path / "rt" / "runtime.png").is_file()
    assert "speed-up" not in res.markdown  # no DLOE column, no ratio
    assert (tmp_path / "rt" / "runtime.csv").read_text().startswith("n_images,pseudo,gttnet")


def test_median_plots(tiny_run, tmp_path):
    from gttnet.evaluate.plots import plot_sweeps
    from gttnet.evaluate.summary import summary_markdown

    recipe, out = tiny_run
    rows = read_rows(out / "errors.csv")
    med = parse_eval_recipe(_tiny(tmp_path, plot_statistic="median"))
    (path,) = plot_sweeps(rows, med, tmp_path)
    assert path.name == "sweep_noise.png" and path.stat().st_size > 1000
    assert "interquartile" in summary_markdown(rows, statistic="median")
    with pytest.raises(EvalRecipeError, match="plot_statistic"):
        parse_eval_recipe(_tiny(tmp_path, plot_statistic="mode"))


def test_a_reconstruction_with_nan_joints_is_counted_apart(tmp_path, monkeypatch):
    """A method that cannot place a joint is not scored as if it had: its row says which joints and why."""
    import gttnet.methods
    from gttnet.methods import Reconstruction, available_methods, register_method

    available_methods()
    monkeypatch.setattr(gttnet.methods, "_REGISTRY", dict(gttnet.methods._REGISTRY))

    @register_method("_test_half", requires="none")
    def _half(obs):
        from gttnet.baselines.pseudo import reconstruct_pseudo

        X = reconstruct_pseudo(obs).points3d.copy()
        X[:, 1] = np.nan
        return Reconstruction(points3d=X)

    data = _tiny(tmp_path, methods=["pseudo", "_test_half"], sequencing=["none"])
    data["sweeps"] = [{"name": "noise", "variable": "capture.sigma_px", "values": [1]}]
    out = evaluate(parse_eval_recipe(data), progress=False)
    rows = {r["method"]: r for r in read_rows(out / "errors.csv")}
    assert rows["pseudo"]["status"] == "ok"
    half = rows["_test_half"]
    assert half["status"] == "error" and half["mpjpe_mm"] == ""
    assert half["note"].startswith("joints left NaN (too few observations): ")
