"""Runtime study of GTT-Net vs DLOE over sequence lengths (paper Fig. 5a), single-threaded by default.

Run:
    python benchmarks/bench_runtime.py                       # 100..600 images, 5 sequences x 3 repeats
    python benchmarks/bench_runtime.py --lengths 100,300 --threads 2 --out runs/eval/runtime

A thin wrapper over :func:`gttnet.evaluate.runtime.run_runtime` (the same study as
``gttnet evaluate recipes/gttnet/eval_paper.yaml --runtime``). GTT-Net uses the bundled model, or an
untrained ``gttnet_base`` when none is installed (inference time does not depend on the weights).
Prints the Markdown speed-up table and writes runtime.csv / runtime.md / runtime.png.
"""

from __future__ import annotations

import argparse
import os

# The runtime target is one core: pin BLAS before numpy loads it.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def main() -> None:
    """Parse arguments, run the study and print its table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--lengths", default="100,200,300,400,500,600", help="Comma-separated image counts.")
    ap.add_argument("--methods", default="dloe,gttnet")
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--repeats", type=int, default=3, help="Timed runs per sequence.")
    ap.add_argument(
        "--sequences", type=int, default=5, help="Test sequences per length (medians over all runs)."
    )
    ap.add_argument("--model", default=None, help="Trained GTT-Net model (default: bundled).")
    ap.add_argument("--threads", type=int, default=1, help="torch threads.")
    ap.add_argument("--device", default="cpu", help="Device of GTT-Net (cpu or cuda); DLOE runs on the CPU.")
    ap.add_argument("--out", default="runs/eval/runtime")
    args = ap.parse_args()

    import torch

    from gttnet.evaluate.recipe import RuntimeSpec
    from gttnet.evaluate.runtime import run_runtime

    torch.set_num_threads(args.threads)
    spec = RuntimeSpec(
        lengths=[int(x) for x in args.lengths.split(",")],
        methods=args.methods.split(","),
        generate=args.recipe,
        repeats=args.repeats,
        sequences=args.sequences,
        model=args.model,
        device=args.device,
    )
    print(run_runtime(spec, args.out).markdown)


if __name__ == "__main__":
    main()
