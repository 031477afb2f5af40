"""Without sequencing: DLOE, GTT-Net, ``stream-sync`` (estimated camera streams, clocks) and ``auto``.

Run:
    python benchmarks/ablation_stream_sync.py --recipes paper,cmu,default --split val --n-seq 10

On ``--n-seq`` captures spread over each recipe's split, under no sequencing: DLOE, GTT-Net,
``stream-sync`` with its check (DLOE where the recovered clocks do not explain the images) and without it
(``fallback=None``), ``auto`` (the same check, falling back on GTT-Net where a bundled model fits); and, as the bound the estimated streams aim at, ``sync`` on the same capture with its true
camera streams (``partial``, the rates estimated from the images as ``stream-sync`` does). Prints a Markdown table: MPJPE (mm) mean and median over the captures, how many
captures ``auto`` beats DLOE and GTT-Net on, and how often the check fell back. Ground truth is used for
scoring only.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _table import spaced  # noqa: E402

from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.data import RecipeSource  # noqa: E402
from gttnet.evaluate.metrics import mpjpe_mm  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402


def main() -> None:
    """Parse arguments, run the methods on every capture and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipes", default="paper,cmu,default", help="names under recipes/gttdata/")
    ap.add_argument("--split", default="val")
    ap.add_argument("--n-seq", type=int, default=10)
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(
        "| recipe | DLOE | GTT-Net | stream-sync | stream-sync, no check | auto | sync, true streams "
        "| auto better than DLOE / GTT-Net | fell back |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    cols = ("dloe", "gttnet", "stream-sync", "unchecked", "auto", "sync")
    for name in args.recipes.split(","):
        src = RecipeSource(load_recipe(f"recipes/gttdata/{name}.yaml"), args.split)
        picks = spaced(len(src), args.n_seq)
        n = len(picks)
        err: dict[str, list[float]] = {k: [] for k in cols}
        fell = 0
        for idx in picks:
            obs, gt = src.view(idx, "none", "orig")
            for method in ("dloe", "gttnet", "stream-sync"):
                err[method].append(mpjpe_mm(reconstruct(obs, method).points3d, gt.points3d))
            raw = reconstruct(obs, "stream-sync", fallback=None)
            err["unchecked"].append(mpjpe_mm(raw.points3d, gt.points3d))
            auto = reconstruct(obs, "auto")
            fell += auto.info["method_ran"] != "stream-sync"
            err["auto"].append(mpjpe_mm(auto.points3d, gt.points3d))
            part, pgt = src.view(idx, "partial", "orig")
            # no rates given: estimated from the images, as stream-sync does (the view's own clocks are dropped)
            part = replace(part, stream_time_s=None)
            err["sync"].append(mpjpe_mm(reconstruct(part, "sync").points3d, pgt.points3d))
        e = {k: np.array(v) for k, v in err.items()}
        cells = " | ".join(f"{e[k].mean():.2f} / {np.median(e[k]):.2f}" for k in cols)
        better = f"{(e['auto'] < e['dloe']).sum()}/{n} / {(e['auto'] < e['gttnet']).sum()}/{n}"
        print(f"| {name}:{args.split} | {cells} | {better} | {fell}/{n} |", flush=True)


if __name__ == "__main__":
    main()
