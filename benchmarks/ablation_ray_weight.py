"""Test-time ablation: GTT-Net with pinned rays against the capture's own noise (``lambda2="auto"``).

Run:
    python benchmarks/ablation_ray_weight.py --recipes paper,cmu,default --split val --n-seq 8 \
        --sequencing none,full

For each recipe and sequencing condition, on ``--n-seq`` captures spread over the split, GTT-Net runs with
the rays pinned (the default) and with per-image ray weights from the noise measured along the camera
streams (:func:`gttnet.geometry.noise.auto_lambda2`). Prints a Markdown table: MPJPE (mm) mean and median
over the captures for both, the median and worst per-capture ratio auto / pinned, how many captures
improve, and the median measured noise (px). Ground truth is used for scoring only.
"""

from __future__ import annotations

import argparse
import os

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
    """Parse arguments, run both ray weights on every capture and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipes", default="paper,cmu,default", help="names under recipes/gttdata/")
    ap.add_argument("--split", default="val")
    ap.add_argument("--n-seq", type=int, default=8)
    ap.add_argument("--sequencing", default="none,full")
    args = ap.parse_args()
    torch.set_num_threads(1)
    print(
        "| recipe | sequencing | pinned mean / median | auto mean / median | ratio median (worst) | better | noise px |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in args.recipes.split(","):
        src = RecipeSource(load_recipe(f"recipes/gttdata/{name}.yaml"), args.split)
        picks = spaced(len(src), args.n_seq)
        n = len(picks)
        for seq in args.sequencing.split(","):
            pinned, auto, noise = [], [], []
            for idx in picks:
                obs, gt = src.view(idx, seq, "orig")
                pinned.append(mpjpe_mm(reconstruct(obs, "gttnet").points3d, gt.points3d))
                rec = reconstruct(obs, "gttnet", lambda2="auto")
                auto.append(mpjpe_mm(rec.points3d, gt.points3d))
                noise.append(np.nan if rec.info["noise_px"] is None else rec.info["noise_px"])
            p, a = np.array(pinned), np.array(auto)
            ratio = a / p
            print(
                f"| {name}:{args.split} | {seq} | {p.mean():.2f} / {np.median(p):.2f} | {a.mean():.2f} / "
                f"{np.median(a):.2f} | {np.median(ratio):.3f} ({ratio.max():.2f}) | {(ratio < 1).sum()}/{n} | "
                f"{np.nanmedian(noise):.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
