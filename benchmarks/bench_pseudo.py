"""Benchmark of pseudo_triangulate for N = 100..600 images of 31 joints on one core.

Run:  python benchmarks/bench_pseudo.py [--sizes 100 200 300 400 500 600] [--block-rows 8 64]

The problem is 4 ring cameras (3 m, f = 1000 px) filming 31 points on a moving body, 10 % missing,
1 px noise; BLAS is pinned to one thread before NumPy is imported. Several ``--block-rows`` are timed
interleaved in the same run (the result is identical for every block size); the table gives the median of
--repeats and each block size's time relative to the first.
Measured 2026-11-24 at N = 600: 0.14-0.15 s on the 2-core dev VM, 0.42 s on the GPU host's Xeon core.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import logging  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from gttnet.geometry.triangulation import pseudo_triangulate  # noqa: E402

log = logging.getLogger("bench_pseudo")


def make_problem(n: int, j: int = 31, *, seed: int = 0):
    """Centres, rays, visibility and camera ids of N images (4 cameras round-robin)."""
    g = np.random.default_rng(seed)
    t = np.arange(n) / 120.0
    X = g.normal(scale=0.3, size=(1, j, 3)) + 0.3 * np.sin(
        2 * np.pi * t[:, None, None] + g.uniform(0, 6, (1, j, 3))
    )
    cam = np.arange(n) % 4
    az = cam * np.pi / 2
    C = np.stack([3 * np.cos(az), 3 * np.sin(az), np.ones(n)], -1)
    r = X - C[:, None] + g.normal(scale=3e-3, size=(n, j, 3))  # ~1 px at 3 m
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    vis = g.uniform(size=(n, j)) >= 0.1
    return C, r, vis, cam


def main() -> None:
    """Time every size and print a table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 200, 300, 400, 500, 600])
    p.add_argument("--joints", type=int, default=31)
    p.add_argument("--block-rows", type=int, nargs="+", default=[8, 64])
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    blocks = args.block_rows
    log.info("%6s %6s %12s %12s %10s", "N", "block", "seconds", "us/pair", "vs first")
    for n in args.sizes:
        C, r, vis, cam = make_problem(n, args.joints)
        times: dict[int, list[float]] = {b: [] for b in blocks}
        for b in blocks:
            pseudo_triangulate(C, r, vis, cam, block_rows=b)
        for _ in range(args.repeats):
            for b in blocks:
                t0 = time.perf_counter()
                pseudo_triangulate(C, r, vis, cam, block_rows=b)
                times[b].append(time.perf_counter() - t0)
        base = statistics.median(times[blocks[0]])
        for b in blocks:
            med = statistics.median(times[b])
            log.info("%6d %6d %12.4f %12.3f %9.2fx", n, b, med, 1e6 * med / (n * n), med / base)


if __name__ == "__main__":
    main()
