"""Fast motion at a low frame rate: every method per capture, each under the sequencing it is given.

Run (the numbers of docs/METHOD.md, "Order sources", and of docs/MODEL_CARD_POINTNET.md):
    python benchmarks/bench_fast_motion.py --n-seq 4 capture.sigma_px=2.0
    python benchmarks/bench_fast_motion.py --n-seq 4 capture.sigma_px=0.0
    python benchmarks/bench_fast_motion.py --recipe recipes/gttdata/topologies.yaml --split val --n-seq 24 \
        --methods dloe@none,gttnet@none --no-defaults

Default data: the held-out quadruped of ``recipes/gttdata/heldout.yaml`` filmed at 10 Hz for 8 s (4 cameras,
320 images): turns and walks fast for the rate, where whole poses are a poor guide to time. ``--methods``
takes ``method@sequencing`` items, a method with options as ``bench_baselines.py`` takes them
(``gttnet:model=runs/x/checkpoint.pt;top_q=4@none``; ``hpf@full`` is HPF given the true timestamps). Prints
one row per capture (MPJPE, mm; ground truth scores the results only) and the mean / median per method.
"""

from __future__ import annotations

import argparse
import logging
import os
import warnings

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from bench_baselines import parse_method  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.errors import GttNetError  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402

DEFAULTS = ["capture.fps_hz=10", "capture.window_s=8"]


def main() -> None:
    """Parse the arguments, run every method on every capture, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttdata/heldout.yaml")
    ap.add_argument("--split", default="test_quadruped")
    ap.add_argument("--n-seq", type=int, default=4)
    ap.add_argument(
        "--methods", default="pseudo@none,dloe@none,gttnet@none,stream-sync@none,auto@none,hpf@full"
    )
    ap.add_argument("--no-defaults", action="store_true", help="do not add " + " ".join(DEFAULTS))
    ap.add_argument("overrides", nargs="*", help="recipe overrides key.sub=value")
    args = ap.parse_args()
    torch.set_num_threads(1)
    logging.disable(logging.WARNING)
    warnings.filterwarnings("ignore")
    recipe = load_recipe(args.recipe, ([] if args.no_defaults else DEFAULTS) + list(args.overrides))
    specs = [tuple(s.rsplit("@", 1)) for s in args.methods.split(",")]
    errors: dict[str, list[float]] = {f"{m}@{q}": [] for m, q in specs}
    print("| capture | images | " + " | ".join(errors) + " |")
    print("|---|---|" + "---|" * len(errors))
    for i in range(args.n_seq):
        sample = build_sample(recipe, args.split, i)[0]
        row = []
        n = 0
        for m, q in specs:
            obs, gt = make_view(sample, q)
            n = obs.n_images
            try:
                name, options = parse_method(m)
                rec = reconstruct(obs, name, **options)
                e = float(1000.0 * np.nanmean(np.linalg.norm(rec.points3d - gt.points3d, axis=-1)))
            except GttNetError as exc:
                print(f"# {sample.motion_name} {m}@{q}: {exc}")
                e = float("nan")
            errors[f"{m}@{q}"].append(e)
            row.append(f"{e:.1f}")
        print(f"| {sample.motion_name} | {n} | " + " | ".join(row) + " |", flush=True)
    print(
        "| mean / median | | "
        + " | ".join(f"{np.nanmean(v):.1f} / {np.nanmedian(v):.1f}" for v in errors.values())
        + " |"
    )


if __name__ == "__main__":
    main()
