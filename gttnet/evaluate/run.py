"""The evaluation harness: run every (condition, sample) job of an EvalRecipe and record per-method errors."""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import logging
import os
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.capture.views import make_view
from gttnet.errors import ModelError, SequencingError
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
from gttnet.evaluate.recipe import EvalRecipe, EvalRecipeError, MethodEntry
from gttnet.methods import Reconstruction, method_spec, reconstruct

__all__ = ["CSV_FIELDS", "Job", "plan_jobs", "run_job", "run_method", "read_rows", "evaluate"]

log = logging.getLogger(__name__)

#: Columns of ``errors.csv`` (``value`` is in plotted units: the recipe value times the sweep's scale).
CSV_FIELDS: tuple[str, ...] = (
    "job_id",
    "condition",
    "variable",
    "value",
    "sequencing",
    "method",
    "sample",
    "n_images",
    "mpjpe_mm",
    "kendall_tau",
    "seconds",
    "status",
    "note",
    "offset_err_frames",
)


@dataclass(frozen=True)
class Job:
    """One (condition, sample) unit of work: every sequencing condition and method on one sequence.

    Args:
        job_id: Stable key in ``errors.csv`` (``condition:value:sample``).
        condition: Sweep name (``base`` without sweeps).
        variable: Overridden generate-recipe key ("" for ``base``).
        value: Value in plotted units.
        overrides: Generate-recipe overrides of this condition.
        dataset: Dataset directory (dataset sources), else None.
        sample: Sample index in the split.
    """

    job_id: str
    condition: str
    variable: str
    value: float
    overrides: tuple[str, ...]
    dataset: str | None
    sample: int


def _n_sequences(recipe: EvalRecipe, dataset: str | None) -> int:
    if recipe.data.n_sequences is not None:
        return recipe.data.n_sequences
    if dataset is not None:
        from gttdata.dataset import CaptureDataset

        return len(CaptureDataset(dataset, split=recipe.data.split, variant=recipe.data.variant))
    from gttdata.generate_plan import n_samples

    return n_samples(_generate_recipe(recipe.data.generate, tuple(recipe.data.overrides)))[recipe.data.split]


def plan_jobs(recipe: EvalRecipe) -> list[Job]:
    """Every job of a recipe, in condition-major order.

    Raises:
        EvalRecipeError: For an unknown method name (checked before any work).
    """
    for m in recipe.methods:
        try:
            method_spec(m.method)
        except ModelError:
            pass  # a missing model is a per-job skip with a note, not a recipe error
        except ValueError as exc:
            raise EvalRecipeError(f"methods.{m.name}: {exc}") from exc
    conds = [("base", "", 0.0, (), recipe.data.dataset)]
    if recipe.sweeps:
        conds = [
            (s.name, s.variable, v.value * s.scale, (f"{s.variable}={v.value}", *v.overrides), v.dataset)
            for s in recipe.sweeps
            for v in s.values
        ]
    base = tuple(recipe.data.overrides)
    jobs = []
    for name, var, value, ovr, ds in conds:
        for i in range(_n_sequences(recipe, ds)):
            jobs.append(Job(f"{name}:{value:g}:{i:04d}", name, var, float(value), base + tuple(ovr), ds, i))
    return jobs


@functools.lru_cache(maxsize=64)
def _generate_recipe(path: str, overrides: tuple[str, ...]):
    from gttdata.recipe import load_recipe

    return load_recipe(path, list(overrides))


def _load_sample(recipe: EvalRecipe, job: Job) -> CaptureSample:
    if job.dataset is not None:
        from gttdata.dataset import CaptureDataset

        return CaptureDataset(job.dataset, split=recipe.data.split, variant=recipe.data.variant).sample(
            job.sample
        )
    from gttdata.generate_plan import build_sample

    gen = _generate_recipe(recipe.data.generate, job.overrides)
    samples = build_sample(gen, recipe.data.split, job.sample)
    names = [s.variant for s in samples]
    if recipe.data.variant not in names:
        raise EvalRecipeError(f"data.variant: expected one of {names}, found {recipe.data.variant!r}")
    return samples[names.index(recipe.data.variant)]


def run_method(obs, entry: MethodEntry) -> Reconstruction:
    """Run one method entry on observations (ground truth never enters).

    Args:
        obs: :class:`~gttdata.capture.views.Observations`.
        entry: Method entry of the recipe; its options go to :func:`gttnet.methods.reconstruct` (e.g.
            ``top_q`` for GTT-Net, the sparsity ablation).

    Returns:
        The timed :class:`Reconstruction`.

    Raises:
        SequencingError: The input lacks the sequencing the method needs.
        ModelError: A GTT-Net model is missing.
    """
    return reconstruct(obs, entry.method, **entry.options)


def _row(job: Job, seq: str, name: str, n: int, **fields) -> dict:
    row = {
        "job_id": job.job_id,
        "condition": job.condition,
        "variable": job.variable,
        "value": f"{job.value:g}",
        "sequencing": seq,
        "method": name,
        "sample": job.sample,
        "n_images": n,
        "mpjpe_mm": "",
        "kendall_tau": "",
        "seconds": "",
        "status": "ok",
        "note": "",
        "offset_err_frames": "",
    }
    row.update(fields)
    row["note"] = " ".join(str(row["note"]).split())  # one line per row: resume counts lines
    return row


def run_job(recipe: EvalRecipe, job: Job, todo: frozenset[tuple[str, str]] | None = None) -> list[dict]:
    """Run every sequencing condition and method of a job (or only the ``todo`` pairs).

    A method that lacks its sequencing or its model, or that fails, gives a row with status ``skipped``
    (or ``error``) and the reason in ``note``; it never stops the run.

    Args:
        recipe: The recipe.
        job: The job.
        todo: ``(sequencing, method name)`` pairs to run; None = all.

    Returns:
        One row per (sequencing, method), keys :data:`CSV_FIELDS`.
    """
    sample = _load_sample(recipe, job)
    rows = []
    for seq in recipe.sequencing:
        obs, gt = make_view(sample, seq, seed=recipe.seed)
        for entry in recipe.methods:
            if todo is not None and (seq, entry.name) not in todo:
                continue
            try:
                rec = run_method(obs, entry)
            except (SequencingError, ModelError) as exc:
                note = f"{exc}" + (f" ({entry.note})" if entry.note else "")
                rows.append(_row(job, seq, entry.name, obs.n_images, status="skipped", note=note))
                continue
            except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
                log.warning("%s %s %s: %s", job.job_id, seq, entry.name, exc)
                rows.append(_row(job, seq, entry.name, obs.n_images, status="error", note=str(exc)[:200]))
                continue
            tau = "" if rec.order is None else f"{kendall_tau(rec.order, gt.global_order):.4f}"
            offset = _offset_error_frames(obs, rec, gt)
            rows.append(
                _row(
                    job,
                    seq,
                    entry.name,
                    obs.n_images,
                    mpjpe_mm=f"{mpjpe_mm(rec.points3d, gt.points3d):.4f}",
                    kendall_tau=tau,
                    seconds=f"{rec.seconds:.4f}",
                    offset_err_frames="" if offset is None else f"{offset:.4f}",
                )
            )
    return rows


def _offset_error_frames(obs, rec: Reconstruction, gt) -> float | None:
    """Median clock error in frames of the recovered clocks, or None.

    Median over cameras of the recovered clock's error in that camera's frames (one common shift
    removed: it is unobservable), for methods that recover clocks (``info["clocks"]``); else None.
    """
    clocks = rec.info.get("clocks")
    if not clocks or "timestamp_s" not in rec.info:
        return None
    err = np.asarray(rec.info["timestamp_s"]) - gt.timestamp_s
    err -= np.median(err)
    per = [abs(float(np.median(err[obs.cam_id == c["camera"]]))) * c["rate_hz"] for c in clocks["cameras"]]
    return float(np.median(per))


def read_rows(path: str | Path) -> list[dict]:
    """Rows of an ``errors.csv`` (rows cut short by a kill are dropped)."""
    p = Path(path)
    if not p.is_file():
        return []
    with p.open(newline="") as f:
        return [r for r in csv.DictReader(f) if None not in r and None not in r.values()]


def _done_pairs(rows: list[dict]) -> dict[str, set[tuple[str, str]]]:
    done: dict[str, set[tuple[str, str]]] = {}
    for r in rows:
        done.setdefault(r["job_id"], set()).add((r["sequencing"], r["method"]))
    return done


def _clean_csv(path: Path) -> list[dict]:
    """Valid rows of an existing CSV; rewrites it when a kill left a torn or malformed last row."""
    if not path.is_file():
        return []
    rows = read_rows(path)
    text = path.read_text()
    if text and (not text.endswith("\n") or text.count("\n") != len(rows) + 1):
        log.info("%s: dropping a torn row left by an interrupted run", path)
        path.unlink()
        _append(path, rows)
    return rows


def _append(path: Path, rows: Iterable[dict]) -> None:
    new = not path.is_file()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        if new:
            w.writeheader()
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())


def _worker_init() -> None:
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # pragma: no cover - torch is a dependency
        pass


def _run_jobs(
    recipe: EvalRecipe, jobs: list[tuple[Job, frozenset]], csv_path: Path, workers: int, progress: bool
) -> None:
    from tqdm import tqdm

    bar = tqdm(total=len(jobs), unit="job", desc=recipe.name, disable=not progress, dynamic_ncols=True)
    try:
        if workers <= 1 or len(jobs) <= 1:
            for job, todo in jobs:
                _append(csv_path, run_job(recipe, job, todo))
                bar.update()
            return
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init) as pool:
            futures = [pool.submit(run_job, recipe, job, todo) for job, todo in jobs]
            for fut in as_completed(futures):
                _append(csv_path, fut.result())
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
    out.mkdir(parents=True, exist_ok=True)
    csv_path = out / "errors.csv"
    if csv_path.exists() and not resume:
        raise EvalRecipeError(f"{csv_path} exists; resume it or choose another output_dir")
    (out / "recipe.json").write_text(json.dumps(dataclasses.asdict(recipe), indent=2) + "\n")
    jobs = plan_jobs(recipe)
    expected = frozenset((s, m.name) for s in recipe.sequencing for m in recipe.methods)
    done = _done_pairs(_clean_csv(csv_path))
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
