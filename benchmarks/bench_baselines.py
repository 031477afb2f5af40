"""Benchmark of the baselines: MPJPE, order recovery and runtime per method and sequencing condition.

Run:
    python benchmarks/bench_baselines.py --n-seq 5
    python benchmarks/bench_baselines.py --n-seq 5 --methods "pseudo,dloe,dloe:lambda2=0.111,dct,hpf"
    python benchmarks/bench_baselines.py --recipe recipes/gttdata/paper.yaml --split test --n-seq 10 \
        capture.sigma_px=4

Data: test samples of the paper recipe (4 cameras on a ~3 m ring, 1000 x 1000 px, f = 1000 px, 30 Hz
staggered, sigma = 2 px, ~300 images) built with ``gttdata.generate_plan.build_sample``, so no shards are
needed. Every method runs under every sequencing condition it supports, single-threaded by default.
Prints a Markdown table (mean over sequences; MPJPE in mm over all images and joints).
"""

from __future__ import annotations

import argparse
import json
import os
import time

# The runtime target is one core: pin BLAS before numpy loads it (a busy machine makes OpenBLAS's
# spinning worker threads cost ~0.3 s per small LAPACK call).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm  # noqa: E402
from gttnet.methods import available_methods, reconstruct  # noqa: E402

LEVEL = {"none": 0, "partial": 1, "full": 2}


def parse_method(spec: str) -> tuple[str, dict]:
    """``"dloe:lambda2=0.11;max_iter=10"`` -> ``("dloe", {"lambda2": 0.11, "max_iter": 10})``.

    Values are JSON; one that is not (``gttnet:model=runs/x/model.pt``) is taken as a string.
    """
    name, _, opts = spec.partition(":")
    options = {}
    for item in filter(None, opts.split(";")):
        k, _, v = item.partition("=")
        try:
            options[k] = json.loads(v)
        except json.JSONDecodeError:
            options[k] = v
    return name, options


def run(
    recipe_path: str,
    split: str,
    n_seq: int,
    methods: list[str],
    overrides: list[str],
    *,
    min_visible: float = 0.0,
) -> list[dict]:
    """One row per (sequence, sequencing, method); a method is ``name`` or ``name:key=value;key=value``.

    Sequences whose fraction of observed joints is below ``min_visible`` (e.g. a subject running out of
    every camera's view) are skipped and reported.
    """
    recipe = load_recipe(recipe_path, overrides)
    needs = available_methods()
    rows = []
    for i in range(n_seq):
        sample = build_sample(recipe, split, i)[0]
        if sample.visible.mean() < min_visible:
            print(
                f"# skip sequence {i} ({sample.motion_name}): {sample.visible.mean():.0%} of joints observed"
            )
            continue
        for seq in ("none", "partial", "full"):
            obs, gt = make_view(sample, seq)
            for m in methods:
                name, options = parse_method(m)
                if LEVEL[needs[name]] > LEVEL[seq]:
                    continue
                t0 = time.perf_counter()
                rec = reconstruct(obs, name, **options)
                rows.append(
                    {
                        "sequence": i,
                        "n_images": obs.n_images,
                        "visible": float(obs.visible.mean()),
                        "sequencing": seq,
                        "method": m,
                        "mpjpe_mm": mpjpe_mm(rec.points3d, gt.points3d),
                        "tau": kendall_tau(rec.order, gt.global_order)
                        if rec.order is not None
                        else float("nan"),
                        "seconds": time.perf_counter() - t0,
                    }
                )
                print(json.dumps(rows[-1]), flush=True)
    return rows


def table(rows: list[dict], methods: list[str]) -> str:
    """Markdown table of means (and the per-sequence win rate of DLOE over pseudo-triangulation)."""
    out = [
        "| sequencing | method | MPJPE mm mean ± std | median | Kendall tau | seconds/seq | N |",
        "|---|---|---|---|---|---|---|",
    ]
    for seq in ("none", "partial", "full"):
        for m in methods:
            sel = [r for r in rows if r["sequencing"] == seq and r["method"] == m]
            if not sel:
                continue
            e = np.array([r["mpjpe_mm"] for r in sel])
            tau = np.nanmean([r["tau"] for r in sel])
            sec = np.mean([r["seconds"] for r in sel])
            n = int(np.mean([r["n_images"] for r in sel]))
            out.append(
                f"| {seq} | {m} | {e.mean():.2f} ± {e.std():.2f} | {np.median(e):.2f} | {tau:.3f} | {sec:.2f} | {n} |"
            )
    for seq in ("none", "partial", "full"):
        p = {r["sequence"]: r["mpjpe_mm"] for r in rows if r["sequencing"] == seq and r["method"] == "pseudo"}
        d = {r["sequence"]: r["mpjpe_mm"] for r in rows if r["sequencing"] == seq and r["method"] == "dloe"}
        common = sorted(set(p) & set(d))
        if common:
            wins = sum(d[k] < p[k] for k in common)
            out.append(f"\nDLOE < pseudo-triangulation under {seq}: {wins}/{len(common)} sequences")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n-seq", type=int, default=3)
    ap.add_argument(
        "--methods", default="pseudo,dloe,dct,hpf", help="comma-separated; options as name:k=v;k=v"
    )
    ap.add_argument("--threads", type=int, default=1, help="torch threads (1 = the 1-core runtime target)")
    ap.add_argument("--min-visible", type=float, default=0.0, help="skip sequences observing fewer joints")
    ap.add_argument("overrides", nargs="*", help="recipe overrides key.sub=value")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    methods = args.methods.split(",")
    rows = run(args.recipe, args.split, args.n_seq, methods, args.overrides, min_visible=args.min_visible)
    print()
    print(table(rows, methods))


if __name__ == "__main__":
    main()
