"""Benchmark of the procedural motion source: seconds per 10 s motion at 120 Hz, per kind.

Run: ``python benchmarks/bench_procedural.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from gttdata.mocap.procedural import PROCEDURAL_KINDS, generate_motion

__all__ = ["bench_kind", "main"]


def bench_kind(kind: str, *, repeats: int, duration_s: float = 10.0, fps_hz: float = 120.0) -> dict:
    """Time ``repeats`` motions of ``kind`` (seeds 0..repeats-1) and summarise a few properties.

    Returns:
        Median and max seconds per motion, max joint speed (m/s), min foot height (m) and root path
        length (m) over the repeats.
    """
    times, vmax, foot, path = [], [], [], []
    for seed in range(repeats):
        t0 = time.perf_counter()
        m = generate_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
        times.append(time.perf_counter() - t0)
        p = m.positions
        vmax.append(float((np.linalg.norm(np.diff(p, axis=0), axis=-1) * fps_hz).max()))
        foot.append(float(p[:, [4, 5, 9, 10], 2].min()))
        path.append(float(np.linalg.norm(np.diff(p[:, 0, :2], axis=0), axis=-1).sum()))
    return {
        "median_s": float(np.median(times)),
        "max_s": float(np.max(times)),
        "vmax_mps": max(vmax),
        "foot_min_m": min(foot),
        "path_m": float(np.median(path)),
    }


def main() -> None:
    """Print one row per kind."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10, help="motions per kind (seeds 0..N-1)")
    args = parser.parse_args()
    generate_motion("walk", seed=0, duration_s=1.0)  # warm-up: imports and first-call costs
    print(f"{'kind':8s} {'median s':>9s} {'max s':>7s} {'vmax m/s':>9s} {'foot min m':>11s} {'path m':>7s}")
    for kind in PROCEDURAL_KINDS:
        r = bench_kind(kind, repeats=args.repeats)
        print(
            f"{kind:8s} {r['median_s']:9.4f} {r['max_s']:7.4f} {r['vmax_mps']:9.2f} "
            f"{r['foot_min_m']:11.3f} {r['path_m']:7.2f}"
        )


if __name__ == "__main__":
    main()
