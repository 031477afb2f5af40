"""Benchmark of clock recovery against known and ignored timestamps.

Benchmark of clock recovery: `sync` (recover clocks, then HPF) against HPF given the true timestamps and
DLOE on the same partial captures, in the same run.

Run (the README's table, "Synchronizing cameras after the fact"):
    python benchmarks/bench_sync.py --recipe recipes/gttdata/paper.yaml --n-seq 10
    python benchmarks/bench_sync.py --recipe recipes/gttdata/cmu.yaml --n-seq 10 capture.sigma_px=5
    python benchmarks/bench_sync.py --recipe recipes/gttdata/sync.yaml --n-seq 10
    python benchmarks/bench_sync.py --recipe recipes/gttdata/cmu.yaml --n-seq 10 --robust

``--robust`` applies the capture section of recipes/gttdata/sync.yaml to any recipe (cameras started up to
5 s apart before the capture, 25 / 30 / 60 / 25 Hz, +-100 ppm drift, 0.5 ms jitter). Every sequence's partial
view (each camera's frames in order, no timestamps) goes to `sync` with the cameras' nominal rates (what a
user knows; taken from the recipe's per-camera rates, never from the timestamps) and to DLOE; its full view
(true timestamps) goes to HPF with time-aware differences (`hpf` with `spacing="time"`, the solver `sync`
runs; on evenly staggered equal-rate captures it equals plain `hpf`). Times are CPU seconds of this process
with one BLAS/torch thread (immune to other processes on a shared machine), medians over sequences and
``--repeats`` runs. The offset error of a capture is the median over its cameras of the recovered clock's
error in frames of that camera, after removing the one shift common to all cameras (unobservable).
"""

from __future__ import annotations

import argparse
import json
import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402

ROBUST = [
    "capture.start_spread_s=5.0",
    "capture.fps_hz=[25.0,30.0,60.0,25.0]",
    "capture.fps_shared=false",
    "capture.stagger=random",
    "capture.drift_ppm={uniform: [-100.0, 100.0]}",
    "capture.jitter_s=0.0005",
]


def _cpu(fn, repeats: int):
    """``(result, median CPU seconds)`` of ``repeats`` calls."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return out, float(np.median(times))


def offset_error_frames(obs, rec, gt) -> np.ndarray:
    """Per-camera error of the recovered clock, frames of that camera, common shift removed."""
    t = np.asarray(rec.info["timestamp_s"])
    err = t - gt.timestamp_s
    err -= np.median(err)
    rows = rec.info["clocks"]["cameras"]
    return np.array([np.median(err[obs.cam_id == r["camera"]]) * r["rate_hz"] for r in rows])


def run(
    recipe_path: str, split: str, n_seq: int, overrides: list[str], *, repeats: int, dloe: bool
) -> list[dict]:
    recipe = load_recipe(recipe_path, overrides)
    rows = []
    warm = make_view(build_sample(recipe, split, 0)[0], "partial")[0]
    reconstruct(warm, "sync")  # first calls pay for imports and caches: keep them out of the timings
    if dloe:
        reconstruct(warm, "dloe")
    for i in range(n_seq):
        sample = build_sample(recipe, split, i)[0]
        fps = {c: float(f) for c, f in enumerate(sample.meta["capture"]["fps_hz"])}  # nominal, per camera
        obs, gt = make_view(sample, "partial")
        full, fgt = make_view(sample, "full")
        rec, t_sync = _cpu(lambda obs=obs, fps=fps: reconstruct(obs, "sync", fps=fps), repeats)
        ref = reconstruct(full, "hpf", spacing="time")
        err = offset_error_frames(obs, rec, gt)
        row = {
            "sequence": i,
            "motion": sample.motion_name,
            "n_images": obs.n_images,
            "sync_mpjpe_mm": mpjpe_mm(rec.points3d, gt.points3d),
            "hpf_true_mpjpe_mm": mpjpe_mm(ref.points3d, fgt.points3d),
            "offset_err_frames": float(np.median(np.abs(err))),
            "offset_err_max_frames": float(np.abs(err).max()),
            "offset_std_frames": float(
                np.median([r["offset_std_s"] * r["rate_hz"] for r in rec.info["clocks"]["cameras"]])
            ),
            "sync_tau": kendall_tau(rec.order, gt.global_order),
            "sync_seconds": t_sync,
            "sync_clock_seconds": float(rec.info["sync_seconds"]),
        }
        if dloe:
            d, t_d = _cpu(lambda obs=obs: reconstruct(obs, "dloe"), repeats)
            row.update({"dloe_mpjpe_mm": mpjpe_mm(d.points3d, gt.points3d), "dloe_seconds": t_d})
        rows.append(row)
        print(json.dumps(row), flush=True)
    return rows


def table(rows: list[dict], label: str) -> str:
    """One Markdown row: means of MPJPE, the ratio to HPF-true, offset errors, CPU seconds and the speed ratio."""
    a = {k: np.array([r[k] for r in rows if k in r]) for k in rows[0]}
    s, h = a["sync_mpjpe_mm"], a["hpf_true_mpjpe_mm"]
    line = (
        f"| {label} | {s.mean():.2f} / {np.median(s):.2f} | {h.mean():.2f} / {np.median(h):.2f} | "
        f"{s.mean() / h.mean():.3f} | {np.median(a['offset_err_frames']):.3f} "
        f"(max {a['offset_err_max_frames'].max():.2f}) | {np.median(a['sync_seconds']):.2f} "
        f"[{a['sync_seconds'].min():.2f}, {a['sync_seconds'].max():.2f}] |"
    )
    if "dloe_seconds" in a and a["dloe_seconds"].size:
        d = a["dloe_mpjpe_mm"]
        ratio = a["dloe_seconds"] / a["sync_seconds"]
        line += (
            f" {d.mean():.2f} / {np.median(d):.2f} | {np.median(a['dloe_seconds']):.2f} "
            f"[{a['dloe_seconds'].min():.2f}, {a['dloe_seconds'].max():.2f}] | {np.median(ratio):.2f}x |"
        )
    else:
        line += " - | - | - |"
    head = (
        "| capture | sync MPJPE mm mean / median | HPF true-time MPJPE | ratio of means | offset error, frames "
        "(median) | sync+solve CPU s median [min, max] | DLOE partial MPJPE | DLOE CPU s | DLOE / sync time |\n"
        "|---|---|---|---|---|---|---|---|---|"
    )
    return head + "\n" + line


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n-seq", type=int, default=3)
    ap.add_argument("--repeats", type=int, default=1, help="timed runs per sequence (median)")
    ap.add_argument("--robust", action="store_true", help="cameras started seconds apart at 25/30/60 Hz")
    ap.add_argument("--no-dloe", action="store_true", help="skip DLOE (accuracy only)")
    ap.add_argument("--label", default=None)
    ap.add_argument("overrides", nargs="*", help="recipe overrides key.sub=value")
    args = ap.parse_args()
    torch.set_num_threads(1)
    ov = (ROBUST if args.robust else []) + list(args.overrides)
    rows = run(args.recipe, args.split, args.n_seq, ov, repeats=args.repeats, dloe=not args.no_dloe)
    label = args.label or " ".join(
        [os.path.basename(args.recipe), *(["robust"] if args.robust else []), *args.overrides]
    )
    print()
    print(table(rows, label))


if __name__ == "__main__":
    main()
