"""The evaluation harness: run an EvalRecipe's pending jobs (in a process pool), then summary and plots."""

from __future__ import annotations

import dataclasses
import json
import logging
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from gttnet.evaluate.jobs import Job, plan_jobs, run_job, run_method
from gttnet.evaluate.recipe import EvalRecipe, EvalRecipeError
from gttnet.evaluate.results import CSV_FIELDS, append_rows, clean_csv, done_pairs, read_rows

__all__ = ["CSV_FIELDS", "Job", "plan_jobs", "run_job", "run_method", "read_rows", "evaluate"]

log = logging.getLogger(__name__)


def _worker_init() -> None:
    """One thread (torch and BLAS) per worker process unless ``--threads``/``GTT_THREADS`` says otherwise."""
    from gttdata.threads import limit_worker_threads

    limit_worker_threads()


def _run_jobs(
    recipe: EvalRecipe, jobs: list[tuple[Job, frozenset]], csv_path: Path, workers: int, progress: bool
) -> None:
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), unit="job", desc=recipe.name, disable=not progress, dynamic_ncols=True)
    try:
        if workers <= 1 or len(jobs) <= 1:
            for job, todo in jobs:
                append_rows(csv_path, run_job(recipe, job, todo))
                bar.update()
            return
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init) as pool:
            futures = [pool.submit(run_job, recipe, job, todo) for job, todo in jobs]
            for fut in as_completed(futures):
                append_rows(csv_path, fut.result())
                bar.update()
    finally:
        bar.close()


def evaluate(
    recipe: EvalRecipe,
    *,
    workers: int | None = None,
    resume: bool = True,
    progress: bool = True,
    plots: bool = True,
) -> Path:
    """Run an evaluation recipe into its run directory and write the summary and plots.

    Args:
        recipe: The validated recipe.
        workers: Worker processes (default: ``recipe.workers``).
        resume: Keep the rows of an existing ``errors.csv`` and run only the missing (job, sequencing,
            method) cells, so adding a method to a finished run runs just that method; when False an
            existing ``errors.csv`` is an error.
        progress: Show a tqdm bar.
        plots: Write the PNG plots.

    Returns:
        The run directory (``errors.csv``, ``summary.md``, ``recipe.json``, ``sweep_*.png``).
    """
    from gttnet.evaluate.plots import plot_sweeps
    from gttnet.evaluate.summary import write_summary

    out = Path(recipe.output_dir)
    csv_path = out / "errors.csv"
    if csv_path.exists() and not resume:
        raise EvalRecipeError(f"{csv_path} exists; resume it or choose another output_dir")
    jobs = plan_jobs(recipe)  # every recipe error (methods, data sources) surfaces before anything is written
    out.mkdir(parents=True, exist_ok=True)
    (out / "recipe.json").write_text(json.dumps(dataclasses.asdict(recipe), indent=2) + "\n")
    expected = frozenset((s, m.name) for s in recipe.sequencing for m in recipe.methods)
    done = done_pairs(clean_csv(csv_path))
    pending = [(j, expected - done.get(j.job_id, set())) for j in jobs]
    pending = [(j, todo) for j, todo in pending if todo]
    log.info(
        "%s: %d jobs, %d done, %d to run", recipe.name, len(jobs), len(jobs) - len(pending), len(pending)
    )
    _run_jobs(recipe, pending, csv_path, workers or recipe.workers, progress)
    ids = {j.job_id for j in jobs}
    rows = [r for r in read_rows(csv_path) if r["job_id"] in ids]
    write_summary(rows, recipe, out / "summary.md")
    if plots:
        plot_sweeps(rows, recipe, out)
    if recipe.runtime is not None:
        from gttnet.evaluate.runtime import run_runtime

        run_runtime(recipe.runtime, out / "runtime", progress=progress)
    return out
