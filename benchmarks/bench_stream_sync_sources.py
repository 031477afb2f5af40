"""Without sequencing: ``stream-sync``'s order sources against HPF given the true timestamps, per capture.

Run (the numbers of docs/METHOD.md, "Time from the images"):
    python benchmarks/bench_stream_sync_sources.py --recipe recipes/gttdata/paper.yaml --n-seq 4 \
        'splits.2.sources.0.kinds=[walk]'
    python benchmarks/bench_stream_sync_sources.py --recipe recipes/gttdata/cmu.yaml --n-seq 4
    python benchmarks/bench_stream_sync_sources.py --recipe recipes/gttdata/sync.yaml --n-seq 4

Each capture's order-free view (``none``, no rate given: the rates are estimated) goes to ``stream-sync``
with its check (DLOE where the kept clocks fail the gate) and without it (``fallback=None``), and to DLOE;
its ``full`` view (true timestamps) to HPF with time-aware differences. Per capture: MPJPE (mm), the ratio
to HPF-true, Kendall tau of the recovered order, the kept source and every source's clock residual and
noise estimate. Ground truth is used for scoring only.
"""

from __future__ import annotations

import argparse
import json
import logging
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402


def run_one(sample) -> dict:
    """Every method on one capture; one JSON-able row."""
    obs, gt = make_view(sample, "none", seed=1)
    full, fgt = make_view(sample, "full")
    raw = reconstruct(obs, "stream-sync", fallback=None)
    checked = reconstruct(obs, "stream-sync")
    hpf = reconstruct(full, "hpf", spacing="time")
    dloe = reconstruct(obs, "dloe")
    h = mpjpe_mm(hpf.points3d, fgt.points3d)
    return {
        "motion": sample.motion_name,
        "n_images": obs.n_images,
        "hpf_true_mm": h,
        "stream_sync_mm": mpjpe_mm(checked.points3d, gt.points3d),
        "method_ran": checked.info["method_ran"],
        "unchecked_mm": mpjpe_mm(raw.points3d, gt.points3d),
        "dloe_mm": mpjpe_mm(dloe.points3d, gt.points3d),
        "ratio_to_hpf_true": mpjpe_mm(checked.points3d, gt.points3d) / h,
        "tau": kendall_tau(raw.order, gt.global_order),
        "dloe_tau": kendall_tau(dloe.order, gt.global_order),
        "kept": raw.info["order_source"],
        "clock_rms_px": raw.info["clock_rms_px"],
        "gate_px": raw.info["gate_px"],
        "sources": {
            k: {m: (round(x, 3) if isinstance(x, float) else x) for m, x in v.items() if m != "error"}
            for k, v in raw.info["order_sources"].items()
        },
        "rates_hz": {
            c: round(r["used_hz"], 3) for c, r in (raw.info["frame_rates"] or {}).get("cameras", {}).items()
        },
    }


def main() -> None:
    """Parse arguments, run every capture, print one JSON row each and a summary line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n-seq", type=int, default=4)
    ap.add_argument("overrides", nargs="*", help="recipe overrides key.sub=value")
    args = ap.parse_args()
    torch.set_num_threads(1)
    logging.getLogger("gttnet.sync").addHandler(logging.NullHandler())  # warnings are in the rows
    recipe = load_recipe(args.recipe, args.overrides)
    rows = []
    for i in range(args.n_seq):
        row = run_one(build_sample(recipe, args.split, i)[0])
        rows.append(row)
        print(json.dumps(row), flush=True)
    s, h = np.array([r["stream_sync_mm"] for r in rows]), np.array([r["hpf_true_mm"] for r in rows])
    d = np.array([r["dloe_mm"] for r in rows])
    u = np.array([r["unchecked_mm"] for r in rows])
    print(
        f"mean MPJPE mm: stream-sync {s.mean():.2f} (unchecked {u.mean():.2f}), HPF-true {h.mean():.2f}, "
        f"DLOE {d.mean():.2f}; ratio of means to HPF-true {s.mean() / h.mean():.3f}; "
        f"fell back {sum(r['method_ran'] != 'stream-sync' for r in rows)} of {len(rows)}"
    )


if __name__ == "__main__":
    main()
