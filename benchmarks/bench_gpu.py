"""Benchmark of a 300-image GTT-Net reconstruct on a GPU: wall time and the GPU's own (kernel) time.

Run:  python benchmarks/bench_gpu.py [--images 300] [--n-seq 5] [--runs 10] [--device cuda]

Data: test samples of the paper recipe with the capture window set to ``images / 120`` seconds (4 cameras
at 30 Hz), ``none`` sequencing, built in memory. Each sequence goes through
:class:`gttnet.model.inference.GTTNetReconstructor` (what ``reconstruct(obs, "gttnet")`` runs; bundled
model, on ``--device``) once untimed (loading,
first-call allocation), then ``--runs`` times:

* wall ms: the whole call, the device synchronised before and after (pseudo-triangulation and the
  neighbourhoods run on the CPU, the network and the DLOE layer on the device);
* GPU ms: the summed time of the device's kernels during one call (``torch.profiler``), i.e. the time the
  call keeps the GPU busy (the issue's bar: < 20 ms at 300 images);
* prepare ms: the CPU part alone (:func:`gttnet.model.inputs.prepare_inputs`).

Medians (min..max) over sequences and runs. Without a CUDA device it says so and exits; ``--device cpu``
runs the same timings on the CPU (GPU ms then ``-``), to check the script.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np
import torch
from _table import fmt

from gttdata.capture.views import make_view
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe
from gttnet.evaluate.metrics import mpjpe_mm
from gttnet.model.inference import GTTNetReconstructor, bundled_model_for
from gttnet.model.inputs import prepare_inputs


def _sync(device: str) -> None:
    if device == "cuda":
        torch.cuda.synchronize()


def kernel_ms(fn, device: str) -> float:
    """Summed device-kernel time of one call of ``fn``, milliseconds (NaN off CUDA)."""
    if device != "cuda":
        return float("nan")
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CUDA]) as prof:
        fn()
        torch.cuda.synchronize()
    total_us = 0.0
    for ev in prof.events():
        if ev.device_type == torch.autograd.DeviceType.CUDA:
            total_us += getattr(ev, "self_device_time_total", None) or getattr(
                ev, "self_cuda_time_total", 0.0
            )
    return total_us / 1000.0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    p.add_argument("--images", type=int, default=300)
    p.add_argument("--n-seq", type=int, default=5)
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--device", default="cuda", choices=("cuda", "cpu"))
    args = p.parse_args()
    if args.device == "cuda" and not torch.cuda.is_available():
        print("no CUDA device: nothing measured (pass --device cpu to check the script on the CPU)")
        sys.exit(0)
    recipe = load_recipe(args.recipe, [f"capture.window_s={args.images / 120.0}"])
    walls, gpus, preps, errs, sizes = [], [], [], [], []
    rec_model = None
    for idx in range(args.n_seq):
        obs, gt = make_view(build_sample(recipe, "test", idx)[0], "none")
        if rec_model is None:
            rec_model = GTTNetReconstructor(
                str(bundled_model_for(obs.skeleton, obs.sequencing)), device=args.device
            )

        def call(obs=obs, model=rec_model):
            return model(obs)  # what reconstruct(obs, "gttnet") runs, on this device

        out = call()  # warm-up
        for _ in range(args.runs):
            _sync(args.device)
            t0 = time.perf_counter()
            out = call()
            _sync(args.device)
            walls.append(1e3 * (time.perf_counter() - t0))
            t0 = time.perf_counter()
            prepare_inputs(obs, k=rec_model.model.config.k)
            preps.append(1e3 * (time.perf_counter() - t0))
        gpus.append(kernel_ms(call, args.device))
        errs.append(mpjpe_mm(out.points3d, gt.points3d))
        sizes.append(obs.n_images)
    name = torch.cuda.get_device_name() if args.device == "cuda" else "CPU"
    print(
        f"\n{args.n_seq} sequences of {int(np.median(sizes))} images (none), {args.runs} runs each, on {name}"
    )
    print("| images | wall ms | GPU ms | prepare (CPU) ms | MPJPE mm |")
    print("|---|---|---|---|---|")
    gpu_cell = "-" if args.device != "cuda" else fmt(gpus, ".1f")
    print(
        f"| {int(statistics.median(sizes))} | {fmt(walls, '.1f')} | {gpu_cell} | {fmt(preps, '.1f')} | "
        f"{fmt(errs, '.1f')} |"
    )


if __name__ == "__main__":
    main()
