"""Figure: the clocks `gttnet sync` recovers for one capture of unsynchronized cameras, against the truth.

Run:
    python benchmarks/plot_sync_clocks.py --out docs/figures/sync_clocks.png

The capture is test sample 0 of recipes/gttdata/sync.yaml (4 cameras started by hand up to 5 s before the
capture, 25 / 30 / 60 / 25 Hz, +-100 ppm drift, sigma = 2 px). Left: each camera's recovered offset
against the true one (seconds; one common shift removed, it is unobservable). Right: the error of every
image's recovered time, in frames of its camera, against its true time.
"""

from __future__ import annotations

import argparse
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.sync import clock_times, recover_clocks  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recipe", default="recipes/gttdata/sync.yaml")
    ap.add_argument("--split", default="test")
    ap.add_argument("--sample", type=int, default=0)
    ap.add_argument("--out", default="docs/figures/sync_clocks.png")
    args = ap.parse_args()
    sample = build_sample(load_recipe(args.recipe), args.split, args.sample)[0]
    obs, gt = make_view(sample, "partial")
    clocks = recover_clocks(obs)
    t = clock_times(obs, clocks)
    shift = np.median(t - gt.timestamp_s)
    true_off = np.array(
        [
            np.median(gt.timestamp_s[obs.cam_id == c] - obs.stream_time_s[obs.cam_id == c])
            for c in clocks.cameras
        ]
    )
    est_off = clocks.offset_s - shift
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8), gridspec_kw={"width_ratios": [1, 1.6]})
    lo, hi = true_off.min() - 0.3, true_off.max() + 0.3
    a.plot([lo, hi], [lo, hi], color="0.7", lw=1)
    for k, c in enumerate(clocks.cameras):
        a.errorbar(
            true_off[k],
            est_off[k],
            yerr=clocks.offset_std_s[k],
            fmt="o",
            label=f"camera {c} ({clocks.rate_hz[k]:g} Hz)",
        )
    a.set_xlabel("true offset (s)")
    a.set_ylabel("recovered offset (s)")
    a.set_title("offset of each camera's clock")
    a.legend(fontsize=7)
    for k, c in enumerate(clocks.cameras):
        sel = obs.cam_id == c
        err = (t[sel] - shift - gt.timestamp_s[sel]) * clocks.rate_hz[k]
        b.plot(
            gt.timestamp_s[sel],
            err,
            ".",
            ms=3,
            label=f"camera {c}: median |error| {np.median(np.abs(err)):.3f} frame",
        )
    b.axhline(0.0, color="0.7", lw=1)
    b.set_xlabel("true capture time (s)")
    b.set_ylabel("recovered - true time (frames)")
    b.set_title(f"{sample.motion_name}: every image's recovered time")
    b.legend(fontsize=7)
    fig.tight_layout()
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    tmp = args.out + ".tmp.png"
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, args.out)
    print(
        f"wrote {args.out}: offsets true {np.round(true_off - true_off.min(), 4)} s, "
        f"recovered {np.round(est_off - true_off.min(), 4)} s"
    )


if __name__ == "__main__":
    main()
