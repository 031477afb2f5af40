"""Training-step benchmark on the CPU: one optimiser step of a training recipe, before and after the speed-ups.

Run:  python benchmarks/bench_train_step.py [--recipe recipes/gttnet/default.yaml] [--repeats 5]
      [--stages 0 1] [--shards DIR]

A fixed batch of the recipe's training sequences (``batch_size`` of them, sequencing conditions
none/partial/full in turn, each run as captured and rotated, as the loop does) is stepped by
every configuration, interleaved repeat by repeat, so all of them see the same machine load:

* ``before``: the libraries' default threads (torch's pool = all cores, OpenBLAS's own pool) and the
  direct (point-major) continuous convolution (``ContinuousConv._forward_reference``);
* ``threads=1``: one torch and one BLAS thread (``train.threads``, the recipe default), direct conv;
* ``conv``: default threads, the channel-major convolution that applies the slot MLP per image;
* ``after``: both (what ``gttnet train`` runs now).

Every configuration starts from the same initial weights and optimiser state and takes ``--repeats``
timed steps after one warm-up; the table gives the median seconds per step, the spread (min-max) and
the speed-up of the median against ``before``. A second table times how one training item is obtained:
simulated from the generate recipe and prepared (pseudo-triangulation, neighbourhoods, targets), read
from shards and prepared (``--shards``, a ``gttdata generate`` output of the same recipe), or loaded
ready-made from the prepared-item cache. The machine load (``os.getloadavg``) is printed: on a shared
machine the absolute numbers move with it, the ratios much less.
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch
from threadpoolctl import threadpool_limits

from gttnet.data import ShardSource, load_item, open_source, prepare_item, save_item
from gttnet.model.continuous_conv import ContinuousConv
from gttnet.model.inputs import random_rotation
from gttnet.model.network import build_model
from gttnet.train.objective import StepObjective
from gttnet.train.recipe import load_train_recipe

CONDITIONS = ("none", "partial", "full")
DEFAULT_THREADS = torch.get_num_threads()


@contextmanager
def _config(threads: int | None, direct_conv: bool):
    """Thread budget (None: library defaults) and convolution formulation for one timed step."""
    fast = ContinuousConv.forward
    torch.set_num_threads(threads or DEFAULT_THREADS)
    limiter = threadpool_limits(limits=threads, user_api="blas") if threads else None
    if direct_conv:
        ContinuousConv.forward = ContinuousConv._forward_reference
    try:
        yield
    finally:
        ContinuousConv.forward = fast
        if limiter is not None:
            limiter.restore_original_limits()
        torch.set_num_threads(DEFAULT_THREADS)


CONFIGS = {"before": (None, True), "threads=1": (1, True), "conv": (None, False), "after": (1, False)}


def _time_items(source, shards, k: int, n: int) -> list[tuple[str, list[float]]]:
    rows: list[tuple[str, list[float]]] = [("recipe: simulate + prepare", [])]
    if shards is not None:
        rows.append(("shards: read + prepare", []))
    rows.append(("prepared item: load", []))
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(n):
            seq = CONDITIONS[i % 3]
            t0 = time.perf_counter()
            item = prepare_item(*source.view(i, seq, "orig"), k=k)
            rows[0][1].append(time.perf_counter() - t0)
            if shards is not None:
                t0 = time.perf_counter()
                prepare_item(*shards.view(i, seq, "orig"), k=k)
                rows[1][1].append(time.perf_counter() - t0)
            path = Path(tmp) / f"{i}.pt"
            save_item(item, path)  # the disk cache's own writer and weights-only reader
            t0 = time.perf_counter()
            load_item(path)
            rows[-1][1].append(time.perf_counter() - t0)
    return rows


def _step(run, config, batch, stage) -> float:
    """Seconds of one optimiser step (forward, backward, Adam) under ``config``."""
    objective, opt = run
    with _config(*config):
        t0 = time.perf_counter()
        loss, _ = objective(batch, stage)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttnet/default.yaml")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--stages", type=int, nargs="+", default=[0, 1], help="stage indices to time")
    ap.add_argument("--shards", default=None, help="shard directory of the recipe's first source")
    ap.add_argument("--items", type=int, default=6, help="items timed in the data table")
    args = ap.parse_args()

    recipe = load_train_recipe(args.recipe)
    spec = recipe.data
    source = open_source(spec, spec.train_split)
    model0 = build_model(recipe.model.builder, **recipe.model.settings)
    k = model0.config.k
    rng = np.random.default_rng(recipe.seed)
    stride = max(1, len(source) // recipe.train.batch_size)
    items = [
        prepare_item(*source.view(i * stride, CONDITIONS[i % 3], "orig"), k=k)
        for i in range(recipe.train.batch_size)
    ]
    batch = []
    for it in items:
        batch += [it, it.rotated(torch.as_tensor(random_rotation(rng), dtype=torch.float32))]
    sizes = [it.inputs.n_images for it in items]
    print(f"recipe {args.recipe}: batch of {len(batch)} sequences (N = {sizes}, each also rotated)")
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at start")

    results: dict[tuple[str, int], list[float]] = {}
    for si in args.stages:
        stage = recipe.stages[si]
        runs = {}
        for name in CONFIGS:
            model = copy.deepcopy(model0)
            runs[name] = (StepObjective(model), torch.optim.Adam(model.parameters(), lr=stage.lr))

        for name in CONFIGS:
            _step(runs[name], CONFIGS[name], batch, stage)  # warm-up
        for _ in range(args.repeats):
            for name in CONFIGS:
                results.setdefault((name, si), []).append(_step(runs[name], CONFIGS[name], batch, stage))

    print(f"load average {os.getloadavg()[0]:.1f} at the end\n")
    print(f"{'stage':<20} {'config':<10} {'s/step':>8} {'min-max':>15} {'steps/s':>8} {'speed-up':>9}")
    for si in args.stages:
        base = statistics.median(results[("before", si)])
        for name in CONFIGS:
            t = results[(name, si)]
            med = statistics.median(t)
            print(
                f"{recipe.stages[si].name:<20} {name:<10} {med:>8.3f} {min(t):>7.3f}-{max(t):<7.3f} "
                f"{1.0 / med:>8.2f} {base / med:>8.2f}x"
            )

    shards = ShardSource(args.shards, spec.train_split) if args.shards else None
    print(f"\n{'training item from':<28} {'median s':>9} {'min-max':>15}")
    with _config(1, False):
        for label, t in _time_items(source, shards, k, args.items):
            print(f"{label:<28} {statistics.median(t):>9.4f} {min(t):>7.4f}-{max(t):<7.4f}")


if __name__ == "__main__":
    main()
