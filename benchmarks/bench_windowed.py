"""Benchmark of windowed against unwindowed reconstruction on 1,440-image captures (partial and full).

Run:  python benchmarks/bench_windowed.py [--n-seq 8] [--methods gttnet,pseudo] [--window auto]

Data: test samples of the paper recipe with a 12 s window (1,440 images of 4 cameras at 30 Hz), built
in memory; samples with fewer than 90 % of the joints observed (the subject leaves the ring) are
skipped, a choice made on the observations alone. Each method runs on the whole capture and window by
window (:func:`gttnet.windowed.reconstruct_windowed`, automatic window: 320 images, 80 overlapping).
The table gives, per method and sequencing, medians over sequences (min..max): MPJPE (mm) of both,
the per-sequence ratio windowed / unwindowed of MPJPE (the bar: within 5 %), Kendall tau of the
recovered order, and seconds with their ratio. BLAS and torch are pinned to one thread.
"""

from __future__ import annotations

import argparse
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import torch  # noqa: E402
from _table import fmt  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402
from gttnet.windowed import auto_window, reconstruct_windowed  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    p.add_argument("--window-s", type=float, default=12.0)
    p.add_argument("--n-seq", type=int, default=8)
    p.add_argument("--methods", default="gttnet,pseudo")
    p.add_argument("--sequencing", default="partial,full")
    p.add_argument("--window", default="auto", help="Images per window, or auto.")
    args = p.parse_args()
    torch.set_num_threads(1)
    recipe = load_recipe(args.recipe, [f"capture.window_s={args.window_s}"])
    methods = args.methods.split(",")
    conds = args.sequencing.split(",")
    keys = ("whole", "win", "ratio", "tau_whole", "tau_win", "s_whole", "s_win")
    res = {(m, c): {k: [] for k in keys} for m in methods for c in conds}
    n_used = idx = 0
    shape = None
    while n_used < args.n_seq and idx < 10 * args.n_seq:
        sample = build_sample(recipe, "test", idx)[0]
        idx += 1
        if sample.visible.mean() < 0.9:
            continue
        n_used += 1
        for c in conds:
            obs, gt = make_view(sample, c)
            length, overlap = (
                auto_window(obs) if args.window == "auto" else (int(args.window), int(args.window) // 4)
            )
            shape = (obs.n_images, length, overlap)
            for m in methods:
                whole = reconstruct(obs, m)
                win = reconstruct_windowed(obs, m, window=length, overlap=overlap)
                r = res[(m, c)]
                e_whole, e_win = mpjpe_mm(whole.points3d, gt.points3d), mpjpe_mm(win.points3d, gt.points3d)
                r["whole"].append(e_whole)
                r["win"].append(e_win)
                r["ratio"].append(e_win / e_whole)
                r["tau_whole"].append(kendall_tau(whole.order, gt.global_order))
                r["tau_win"].append(kendall_tau(win.order, gt.global_order))
                r["s_whole"].append(whole.seconds)
                r["s_win"].append(win.seconds)
        print(f"sequence {idx - 1} done", flush=True)
    n, length, overlap = shape
    print(
        f"\n{n_used} sequences of {n} images; windows of {length} images, {overlap} overlapping; median (min..max)"
    )
    print(
        "| method | sequencing | MPJPE whole mm | MPJPE windowed mm | windowed / whole | tau whole | tau windowed | s whole | s windowed | speed-up |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for (m, c), r in res.items():
        speed = [a / b for a, b in zip(r["s_whole"], r["s_win"], strict=True)]
        print(
            f"| {m} | {c} | {fmt(r['whole'], '.1f')} | {fmt(r['win'], '.1f')} | {fmt(r['ratio'], '.3f')} | "
            f"{fmt(r['tau_whole'], '.3f')} | {fmt(r['tau_win'], '.3f')} | {fmt(r['s_whole'])} | {fmt(r['s_win'])} | "
            f"{fmt(speed, '.1f')}x |"
        )


if __name__ == "__main__":
    main()
