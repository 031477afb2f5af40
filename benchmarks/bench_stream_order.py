"""Cost of GTT-Net's per-camera stream ordering without sequencing, against DLOE, in one run.

Run:
    python benchmarks/bench_stream_order.py                      # 300 images, 5 sequences x 3 runs
    python benchmarks/bench_stream_order.py --n-seq 5 --repeats 3 capture.window_s=5.0   # ~600 images

Times, on one thread and in the same run, over test captures of the paper recipe under ``none``:
DLOE; GTT-Net as ``--method gttnet`` runs it (streams ordered first, order recovered); the same with
``stream_order=False``; and the bare network (inputs, U-Net encoder, DLOE layer; no order recovery).
Prints a Markdown table: median seconds (min..max) over sequences x runs, and DLOE's median over each.
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402
from gttnet.model.inference import GTTNetReconstructor, bundled_model_for  # noqa: E402
from gttnet.model.inputs import prepare_inputs  # noqa: E402


def main() -> None:
    """Parse arguments, time the four configurations and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n-seq", type=int, default=5)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("overrides", nargs="*", help="recipe overrides key.sub=value")
    args = ap.parse_args()
    torch.set_num_threads(1)
    recipe = load_recipe(args.recipe, args.overrides)
    samples = [build_sample(recipe, args.split, i)[0] for i in range(args.n_seq)]
    views = [make_view(s, "none", seed=0)[0] for s in samples]
    path = str(bundled_model_for(views[0].skeleton, "none"))
    ordered = GTTNetReconstructor(path, device="cpu", stream_order=True)
    plain = GTTNetReconstructor(path, device="cpu", stream_order=False)
    net = plain.model

    @torch.no_grad()
    def bare(obs):
        return net([prepare_inputs(obs, k=net.config.k)], solve=True, decode=False)[0].x_est

    runs = {
        "DLOE": lambda obs: reconstruct(obs, "dloe"),
        "GTT-Net (--method gttnet)": ordered,
        "GTT-Net, stream_order=False": plain,
        "bare network": bare,
    }
    seconds: dict[str, list[float]] = {name: [] for name in runs}
    for obs in views:
        for fn in runs.values():
            fn(obs)  # warm-up: model load, caches
        for _ in range(args.repeats):
            for name, fn in runs.items():  # interleaved: a load change hits every configuration alike
                t0 = time.perf_counter()
                fn(obs)
                seconds[name].append(time.perf_counter() - t0)
    n_img = int(np.median([v.n_images for v in views]))
    dloe = float(np.median(seconds["DLOE"]))
    print(
        f"# Stream ordering cost: {args.n_seq} sequences x {args.repeats} runs, ~{n_img} images, one thread\n"
    )
    print("| configuration | seconds, median (min..max) | DLOE / this |")
    print("|---|---|---|")
    for name, t in seconds.items():
        med = float(np.median(t))
        print(f"| {name} | {med:.3f} ({min(t):.3f}..{max(t):.3f}) | {dloe / med:.1f}x |")


if __name__ == "__main__":
    main()
