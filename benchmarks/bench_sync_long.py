"""Benchmark of clock recovery over long drifting recordings: cost against length, drift and timing error.

Run:  python benchmarks/bench_sync_long.py [--sizes 7200 24000 72000] [--runs 3] [--drift-ppm 100]

Data: ``recipes/gttdata/long.yaml`` (4 cameras at 30 Hz, one dancer inside the ring) cut to ``size / 120``
seconds, with every camera's clock drawn ``uniform(-drift, +drift)`` ppm off, cameras started up to 1 s
apart at random sub-frame offsets, built in memory. The partial view (each camera's frames in order, no
timestamps) goes to :func:`gttnet.sync.recover_clocks` (nominal 30 Hz) three ways:

* ``piecewise``: the default for recordings over 40 s: the full offset search on the first 20 s, then
  offsets and drift from 8 windows spread over the whole recording (what windowed reconstruction runs);
* ``first 2,400 images``: clocks from the recording's first 2,400 images only (what windowed
  reconstruction ran before; drift is not estimated on 20 s);
* ``one piece``: the full search and refinement over every image (``piecewise=False``), up to
  ``--max-whole`` images.

Columns: CPU seconds of this process (one BLAS thread; immune to other processes on a shared machine)
and wall seconds, medians (min..max) over ``--runs`` runs; CPU microseconds per image and that cost as a
ratio to the smallest size's (1.0 = linear); the largest error of the recovered drifts (ppm, relative to
the cameras' mean, as recovered) against the simulation's, and the largest and 99th-percentile timing
error of an image in frames over the whole recording, after removing the one shift and rate common to
all cameras (unobservable). Ground truth scores only.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from _table import fmt  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.sync import clock_times, local_times, per_camera_rates, recover_clocks  # noqa: E402

RECIPE = Path(__file__).resolve().parents[1] / "recipes" / "gttdata" / "long.yaml"
PREFIX_IMAGES = 2400


def capture(size: int, drift_ppm: float):
    """Partial view and ground truth of the long recipe cut to ``size`` images, with drifting clocks."""
    secs = size / 120.0
    recipe = load_recipe(
        RECIPE,
        [
            f"capture.window_s={secs}",
            f"splits.0.sources.0.duration_s={secs + 1.0}",
            f"capture.drift_ppm={{uniform: [{-drift_ppm}, {drift_ppm}]}}",
            "capture.start_spread_s=1.0",
            "capture.stagger=random",
        ],
    )
    return make_view(build_sample(recipe, "test", 0)[0], "partial")


def true_drift_ppm(obs, gt) -> np.ndarray:
    """Each camera's clock-rate error against the mean of the cameras, ppm, from the true times."""
    tau = local_times(obs, per_camera_rates(obs.cam_id, None))
    slope = [
        np.polyfit(tau[obs.cam_id == c], gt.timestamp_s[obs.cam_id == c], 1)[0] for c in np.unique(obs.cam_id)
    ]
    d = (np.asarray(slope) - 1.0) * 1e6
    return d - d.mean()


def recover(obs, config: str):
    if config == "piecewise":
        return recover_clocks(obs)
    if config == "one piece":
        return recover_clocks(obs, piecewise=False)
    cam = np.asarray(obs.cam_id)
    per = PREFIX_IMAGES // np.unique(cam).size
    order = np.lexsort((obs.stream_index, cam))
    keep = np.concatenate([order[cam[order] == c][:per] for c in np.unique(cam)])
    return recover_clocks(obs.take(np.sort(keep)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[7200, 24000, 72000])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--drift-ppm", type=float, default=100.0)
    p.add_argument("--max-whole", type=int, default=7200, help="Largest size recovered in one piece.")
    args = p.parse_args()
    rows = []
    for size in args.sizes:
        obs, gt = capture(size, args.drift_ppm)
        truth = true_drift_ppm(obs, gt)
        for config in ("piecewise", "first 2,400 images", "one piece"):
            if config == "one piece" and size > args.max_whole:
                continue
            cpus, walls = [], []
            for _ in range(args.runs):
                t0, c0 = time.perf_counter(), time.process_time()
                clocks = recover(obs, config)
                cpus.append(time.process_time() - c0)
                walls.append(time.perf_counter() - t0)
            err = clock_times(obs, clocks) - gt.timestamp_s
            err -= np.polyval(np.polyfit(gt.timestamp_s, err, 1), gt.timestamp_s)
            frames = np.abs(err) * 30.0
            rows.append(
                (obs.n_images, config, cpus, walls, np.abs(clocks.drift_ppm - truth).max(), frames, truth)
            )
            print(f"{obs.n_images} {config}: {statistics.median(cpus):.2f} CPU s", flush=True)
    base: dict[str, float] = {}
    for n, config, cpus, *_ in rows:
        base.setdefault(config, statistics.median(cpus) / n)
    print(
        f"\n`recover_clocks` on partial views of long.yaml, drift uniform +-{args.drift_ppm:g} ppm; median (min..max)"
    )
    print(
        "| images | clocks from | CPU s | wall s | CPU us/image | per-image vs smallest | "
        "drift error ppm (max) | timing error frames (max) | (99th pct) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for n, config, cpus, walls, drift_err, frames, _ in rows:
        med = statistics.median(cpus)
        print(
            f"| {n:,} | {config} | {fmt(cpus)} | {fmt(walls)} | {1e6 * med / n:.0f} | {med / n / base[config]:.2f} | "
            f"{drift_err:.1f} | {frames.max():.3f} | {np.percentile(frames, 99):.3f} |"
        )
    print("\ntrue drifts (ppm, against the cameras' mean):", np.round(rows[-1][-1], 1).tolist())


if __name__ == "__main__":
    main()
