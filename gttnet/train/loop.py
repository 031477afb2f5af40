"""The training loop: the cascade of stages as a for-loop over one data stream, with validation and checkpoints."""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import math
import os
import random
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from tqdm import tqdm

from gttdata.fileio import OutputLock
from gttdata.threads import requested_threads
from gttnet.data import EpochStream, SequenceDataset, TrainItem, collate_items, open_source
from gttnet.model.inference import load_model, save_model
from gttnet.model.inputs import random_rotation
from gttnet.model.network import GTTNet, build_model
from gttnet.train import distributed
from gttnet.train.checkpoint import (
    CHECKPOINT_NAME,
    LoopState,
    load_checkpoint,
    save_checkpoint,
    set_rng_states,
)
from gttnet.train.objective import StepObjective
from gttnet.train.recipe import TrainRecipe, recipe_to_dict, run_folder, saved_run_recipe
from gttnet.train.rundir import open_run
from gttnet.train.runlog import RunLog, git_sha, plot_loss_curve
from gttnet.train.stages import Stage, freeze_parts
from gttnet.train.threads import limit_cpu_threads
from gttnet.train.validate import validate

__all__ = ["RunResult", "train"]

log = logging.getLogger(__name__)


@dataclass
class RunResult:
    """Outcome of :func:`train`.

    Args:
        run_dir: The run directory.
        state: Final loop state (history included).
        model: The trained network.
        finished: False when stopped early by ``max_steps`` (continue with ``out=run_dir, resume=True``).
    """

    run_dir: Path
    state: LoopState
    model: GTTNet
    finished: bool


def _stage_length(stage: Stage, steps_per_epoch: int) -> int:
    if stage.steps is not None:
        return stage.steps
    assert stage.epochs is not None  # a stage has exactly one of steps / epochs (checked when parsed)
    return stage.epochs * steps_per_epoch


def _lr(stage: Stage, state: LoopState, total: int) -> float:
    if stage.schedule == "cosine":
        t = min(state.stage_step / max(total, 1), 1.0)
        return stage.min_lr + (stage.lr - stage.min_lr) * 0.5 * (1.0 + math.cos(math.pi * t))
    return state.lr


@dataclass
class _Context:
    """Everything one training run shares between stages."""

    recipe: TrainRecipe
    run_dir: Path
    model: GTTNet
    dev: torch.device
    dtype: torch.dtype
    rank: int
    world: int
    logger: RunLog
    batches: Iterator[list[TrainItem]]
    val_items: list[TrainItem]
    steps_per_epoch: int


def _prepare(
    recipe: TrainRecipe, payload: dict | None, out, device: str | None
) -> tuple[_Context, LoopState]:
    device_name = device or recipe.train.device
    rank, world, local = distributed.setup(device_name)
    dev = distributed.select_device(device_name, local_rank=local)
    if dev.type == "cpu":  # the command line's --threads / GTT_THREADS win over the recipe's train.threads
        threads = requested_threads()
        limit_cpu_threads(threads if threads is not None else recipe.train.threads)
    dtype = torch.float64 if recipe.train.dtype == "float64" else torch.float32
    run_dir = distributed.agree_on_path(out, world)
    if rank == 0:
        run_dir.mkdir(parents=True, exist_ok=True)
        if payload is None:
            (run_dir / "recipe.yaml").write_text(yaml.safe_dump(recipe_to_dict(recipe), sort_keys=False))
    logger = RunLog(run_dir, rank == 0)
    random.seed(recipe.seed)
    np.random.seed(recipe.seed)  # noqa: NPY002 (third-party code may use the global generator)
    torch.manual_seed(recipe.seed)
    model = build_model(recipe.model.builder, **recipe.model.settings).to(device=dev, dtype=dtype)
    state = LoopState()
    if payload is not None:
        model.load_state_dict(payload["model"])
        state = payload["state"]
        set_rng_states(payload["rng"])
        dropped = logger.drop_after(state.global_step)
        if dropped:
            log.info("resume at step %d: dropped %d log records written after it", state.global_step, dropped)
    elif recipe.model.init is not None:
        try:  # non-architecture settings (Q, lambdas, solver) may differ from the initial model's
            model.load_state_dict(load_model(recipe.model.init).state_dict())
        except RuntimeError as exc:
            raise ValueError(
                f"model.init {recipe.model.init}: architecture differs ({str(exc).splitlines()[0]})"
            ) from exc
    if payload is None:
        logger.write({"kind": "meta", "global_step": 0, "git_sha": git_sha(), "seed": recipe.seed,
                      "device": str(dev), "world": world, "recipe": recipe_to_dict(recipe)})  # fmt: skip
    n_params = sum(p.numel() for p in model.parameters())
    log.info("run %s on %s (world %d): %d parameters", run_dir, dev, world, n_params)

    spec = recipe.data
    common: dict[str, Any] = {
        "k": model.config.k,
        "sequencing": spec.sequencing,
        "seed": recipe.seed,
        "cache": spec.cache,
        "stream_order": spec.stream_order,
    }
    cache = run_dir / "item_cache"
    train_set = SequenceDataset(
        open_source(spec, spec.train_split), variants=spec.variants, cache_dir=cache / "train", **common
    )
    val_set = SequenceDataset(
        open_source(spec, spec.val_split, limit="max_val"),
        variants=spec.variants[:1],
        cache_dir=cache / "val",
        **common,
    )
    val_items = [val_set[(i, 0, c)].to(dev, dtype) for i in range(len(val_set)) for c in val_set.conditions]
    n_train = len(train_set)
    per_rank = n_train // world
    stream = EpochStream(n_train, seed=recipe.seed, rank=rank, world=world,
                         start_epoch=state.keys_consumed // per_rank, start_pos=state.keys_consumed % per_rank)  # fmt: skip
    workers = spec.num_workers
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if dev.type == "cpu" and workers > cores:
        # Item preparation is CPU-bound: more workers than cores only fight the training process.
        log.info("data.num_workers %d > %d cores: using %d workers", workers, cores, cores)
        workers = cores
    loader = torch.utils.data.DataLoader(
        train_set, batch_size=recipe.train.batch_size, sampler=stream, collate_fn=collate_items,
        num_workers=workers, persistent_workers=workers > 0, worker_init_fn=_worker_init,
    )  # fmt: skip
    spe = recipe.train.steps_per_epoch or max(1, per_rank // recipe.train.batch_size)
    ctx = _Context(recipe, run_dir, model, dev, dtype, rank, world, logger, iter(loader), val_items, spe)
    return ctx, state


def _worker_init(_worker_id: int) -> None:
    """DataLoader workers prepare items with numpy: one BLAS thread each (torch is already single-threaded)."""
    limit_cpu_threads(1)


def _step(ctx: _Context, step_fn, optimizer, trainable, stage: Stage, state: LoopState, lr: float):
    items = [it.to(ctx.dev, ctx.dtype) for it in next(ctx.batches)]
    rng = np.random.default_rng(np.random.SeedSequence([ctx.recipe.seed, 31337, state.global_step, ctx.rank]))
    batch = []
    for it in items:
        R = torch.as_tensor(
            random_rotation(rng, mode=ctx.recipe.train.rotation), dtype=ctx.dtype, device=ctx.dev
        )
        batch += [it, it.rotated(R)]
    for group in optimizer.param_groups:
        group["lr"] = lr
    amp = ctx.recipe.train.amp and ctx.dev.type == "cuda"
    with torch.autocast(device_type=ctx.dev.type, dtype=torch.bfloat16, enabled=amp):
        loss, parts = step_fn(batch, stage)
    optimizer.zero_grad(set_to_none=True)
    if loss.requires_grad:  # not when every term is constant (e.g. only l_X on full items: the time chain)
        loss.backward()
        if ctx.recipe.train.grad_clip is not None:
            torch.nn.utils.clip_grad_norm_(trainable, ctx.recipe.train.grad_clip)
        optimizer.step()
    value = float(loss.detach())
    if not math.isfinite(value):
        raise FloatingPointError(f"stage {stage.name!r} step {state.stage_step + 1}: loss is {value}")
    return value, {k: float(v.detach()) for k, v in parts.items()}, len(batch)


def _validate_and_schedule(ctx: _Context, stage: Stage, si: int, state: LoopState, lr: float) -> None:
    val = validate(ctx.model, stage, ctx.val_items)
    rec = {"kind": "val", "stage": stage.name, "stage_index": si, "step": state.stage_step,
           "global_step": state.global_step, "lr": lr, **val}  # fmt: skip
    state.history.append(rec)
    ctx.logger.write(rec)
    if val["loss"] < state.best_val * (1.0 - 1e-4):
        state.best_val, state.bad_vals = val["loss"], 0
        return
    state.bad_vals += 1
    if stage.schedule == "plateau" and state.bad_vals > stage.plateau_patience:
        state.lr, state.bad_vals = max(state.lr * stage.plateau_factor, stage.min_lr), 0


def window_means(window: list[tuple[float, dict[str, float]]]) -> dict[str, float]:
    """Mean of each loss part over the steps of a log window that have it, keyed ``loss_<part>``.

    A part may be missing from some steps: the PointNet reconstruction loss only exists on batches
    holding a named training topology (augmented topologies have no decoder).
    """
    names = sorted({k for _, parts in window for k in parts})
    return {f"loss_{k}": float(np.mean([p[k] for _, p in window if k in p])) for k in names}


def _save(ctx: _Context, optimizer, state: LoopState) -> None:
    if ctx.rank == 0:
        save_checkpoint(
            ctx.run_dir, model=ctx.model, optimizer=optimizer, state=state, recipe=recipe_to_dict(ctx.recipe)
        )


def _finish(ctx: _Context, state: LoopState) -> None:
    distributed.check_replicas(ctx.model, ctx.world)
    if ctx.rank != 0:
        return
    last_val: dict = next((r for r in reversed(state.history) if r["kind"] == "val"), {})
    card = {"recipe": recipe_to_dict(ctx.recipe), "git_sha": git_sha(), "steps": state.global_step,
            "validation": last_val, "trained_on": str(ctx.dev), "world": ctx.world}  # fmt: skip
    save_model(ctx.run_dir / "model.pt", ctx.model, card=card)
    plot_loss_curve(ctx.run_dir, state.history)
    shutil.rmtree(ctx.run_dir / "item_cache", ignore_errors=True)


def train(
    recipe: TrainRecipe | None = None,
    *,
    out: str | Path | None = None,
    device: str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    max_steps: int | None = None,
    progress: bool = True,
) -> RunResult:
    """Run (or resume) a training cascade: for each stage, Adam steps over the data stream.

    Each step draws ``batch_size`` sequences and runs each twice (as captured and globally rotated, F^GR),
    all packed into one network call; validation runs every epoch and at the end of every stage; a
    checkpoint holding all state is written every ``checkpoint_every`` steps and at every stage's end.

    Args:
        recipe: The recipe; None to resume the run in ``out`` with the recipe it saved.
        out: Run directory (default: the recipe's ``output_dir``, else ``runs/<name>``). One that already
            holds a run is refused unless ``resume`` or ``overwrite`` is given; one process writes it at a
            time.
        device: Overrides ``recipe.train.device`` (``auto``, ``cpu``, ``cuda``).
        resume: Continue the run in ``out`` exactly where it stopped (same recipe only, ``output_dir``
            aside; a directory without a checkpoint starts afresh).
        overwrite: Delete an earlier run in ``out`` first.
        max_steps: Stop (with a checkpoint) after this many steps in this call; None: run to the end.
        progress: Show a tqdm progress bar.

    Returns:
        :class:`RunResult`.
    """
    if recipe is None and (out is None or not resume):
        raise ValueError("train() needs a recipe, or out=RUN_DIR with resume=True to continue that run")
    folder = Path(out) if out is not None else run_folder(recipe)  # type: ignore[arg-type]
    rank0 = int(os.environ.get("RANK", "0")) == 0
    # The lock comes first: a second trainer must not inspect or delete (--overwrite) a run in progress.
    with OutputLock(folder, "gttnet train") if rank0 else contextlib.nullcontext():
        if rank0:
            recipe, payload = open_run(recipe, out=folder, resume=resume, overwrite=overwrite)
        elif recipe is None:
            payload = load_checkpoint(folder)
            recipe = saved_run_recipe(payload["recipe"], folder)
        else:
            recipe = dataclasses.replace(recipe, output_dir=str(folder))
            payload = load_checkpoint(folder) if resume and (folder / CHECKPOINT_NAME).is_file() else None
        return _train(recipe, payload, folder, device, max_steps, progress)


def _train(recipe: TrainRecipe, payload: dict | None, out, device, max_steps, progress) -> RunResult:
    """The body of :func:`train` once the run directory is decided (and locked)."""
    ctx, state = _prepare(recipe, payload, out, device)
    lengths = [_stage_length(s, ctx.steps_per_epoch) for s in recipe.stages]
    bar = tqdm(
        total=sum(lengths), initial=state.global_step, disable=not progress or ctx.rank != 0, unit="step"
    )
    objective = StepObjective(ctx.model)
    done_here = 0
    for si in range(state.stage_index, len(recipe.stages)):
        stage, total = recipe.stages[si], lengths[si]
        trainable = freeze_parts(ctx.model, stage.frozen)
        optimizer = torch.optim.Adam(trainable, lr=stage.lr)
        if payload is not None and state.stage_step > 0:
            optimizer.load_state_dict(payload["optimizer"])
        else:
            state.stage_step, state.lr, state.best_val, state.bad_vals = 0, stage.lr, float("inf"), 0
        payload = None
        step_fn = distributed.wrap(objective, ctx.dev, ctx.world)
        t_last, seqs, window = time.perf_counter(), 0, []
        while state.stage_step < total:
            if max_steps is not None and done_here >= max_steps:
                _save(ctx, optimizer, state)
                bar.close()
                distributed.teardown(ctx.world)
                return RunResult(ctx.run_dir, state, ctx.model, finished=False)
            lr = _lr(stage, state, total)
            loss, parts, n_seq = _step(ctx, step_fn, optimizer, trainable, stage, state, lr)
            state.stage_step, state.global_step = state.stage_step + 1, state.global_step + 1
            state.keys_consumed += recipe.train.batch_size
            done_here, seqs = done_here + 1, seqs + n_seq
            window.append((loss, parts))
            bar.update(1)
            if state.stage_step % recipe.train.log_every == 0 or state.stage_step in (1, total):
                rate = seqs / max(time.perf_counter() - t_last, 1e-9)
                # Means over the steps since the last record: single steps swing by 100x between captures.
                mean = window_means(window)
                rec = {"kind": "train", "stage": stage.name, "stage_index": si, "step": state.stage_step,
                       "global_step": state.global_step, "lr": lr, "loss": float(np.mean([v for v, _ in window])),
                       "loss_last": loss, "window": len(window), **mean, "seq_per_s": rate}  # fmt: skip
                state.history.append(rec)
                ctx.logger.write(rec)
                bar.set_postfix(stage=stage.name, loss=f"{loss:.4g}", seq_s=f"{rate:.1f}")
                t_last, seqs, window = time.perf_counter(), 0, []
            if state.stage_step % ctx.steps_per_epoch == 0 or state.stage_step == total:
                _validate_and_schedule(ctx, stage, si, state, lr)
            if state.stage_step % recipe.train.checkpoint_every == 0 and state.stage_step < total:
                _save(ctx, optimizer, state)
        state.stage_index, state.stage_step = si + 1, 0
        _save(ctx, optimizer, state)
    bar.close()
    _finish(ctx, state)
    distributed.teardown(ctx.world)
    return RunResult(ctx.run_dir, state, ctx.model, finished=True)
