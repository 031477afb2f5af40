"""Evaluation jobs: plan the (condition, sample) units of an EvalRecipe and run every method on one."""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.capture.views import make_view
from gttnet.errors import ModelError, SequencingError
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
from gttnet.evaluate.recipe import EvalRecipe, EvalRecipeError, MethodEntry
from gttnet.evaluate.results import make_row
from gttnet.methods import Reconstruction, method_spec, reconstruct

__all__ = ["Job", "plan_jobs", "run_job", "run_method"]

log = logging.getLogger(__name__)


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
        RecipeError: A condition's data recipe is missing or invalid (also checked before any work).
    """
    for m in recipe.methods:
        try:
            method_spec(m.method)
        except ModelError:
            pass  # a missing model is a per-job skip with a note, not a recipe error
        except ValueError as exc:
            raise EvalRecipeError(f"methods.{m.name}: {exc}") from exc
    conds: list[tuple[str, str, float, tuple[str, ...], str | None]] = [
        ("base", "", 0.0, (), recipe.data.dataset)
    ]
    if recipe.sweeps:
        conds = [
            (s.name, s.variable, v.value * s.scale, (f"{s.variable}={v.value}", *v.overrides), v.dataset)
            for s in recipe.sweeps
            for v in s.values
        ]
    base = tuple(recipe.data.overrides)
    jobs = []
    for name, var, value, ovr, ds in conds:
        if ds is None:  # load each condition's data recipe now: a bad path or value fails before any write
            _generate_recipe(recipe.data.generate, base + tuple(ovr))
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
                rows.append(make_row(job, seq, entry.name, obs.n_images, status="skipped", note=note))
                continue
            except (ValueError, RuntimeError, np.linalg.LinAlgError) as exc:
                log.warning("%s %s %s: %s", job.job_id, seq, entry.name, exc)
                rows.append(make_row(job, seq, entry.name, obs.n_images, status="error", note=str(exc)[:200]))
                continue
            if (
                rec.nan_joints.size
            ):  # not comparable with a full reconstruction: counted apart, with the reason
                names = ", ".join(obs.skeleton.joint_names[j] for j in rec.nan_joints)
                note = f"joints left NaN (too few observations): {names}"[:200]
                rows.append(make_row(job, seq, entry.name, obs.n_images, status="error", note=note))
                continue
            tau = "" if rec.order is None else f"{kendall_tau(rec.order, gt.global_order):.4f}"
            offset = _offset_error_frames(obs, rec, gt)
            rows.append(
                make_row(
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
