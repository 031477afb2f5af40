"""Benchmark of the X-step solvers: pinned (dense torch, sparse SuperLU) against the dense 3N reference.

Run:  python benchmarks/bench_xstep.py [--sizes 100 200 300 500 1000] [--threads 1] [--max-dense-gb 6]

Each problem is N images of J joints from 4 ring cameras 3 m away, 10 % of joints missing, and an
affinity with Q ~ 3 links per row (the true temporal chain, as GTT-Net's Q = 2 plus a within-stream
link). Every method is timed in the same run; the dense reference is skipped (and marked so, never
extrapolated) where its (J, 3N, 3N) system would exceed --max-dense-gb. Times are the median of
--repeats runs after one warm-up, forward only and forward + backward w.r.t. A.

Measured 2026-11-24 (Xeon, 1 thread / 16 threads; H100), N = 500, seconds (speed-up vs reference):
    CPU 1 thread:   reference 3.51, pinned-sparse 0.110 (32x; 45x with backward), pinned-dense 0.565 (6x)
    CPU 16 threads: reference 0.47, pinned-dense 0.109 (4.3x), pinned-sparse 0.121 (3.9x); N = 1000: 11x
    CUDA:           reference 0.059, pinned-dense 0.012 (4.9x); N = 1000: 0.025 vs 0.212 (8.5x)
"""

from __future__ import annotations

import argparse
import logging
import statistics
import time

import numpy as np
import torch

from gttnet.solvers import solve_structure, solve_structure_dense

log = logging.getLogger("bench_xstep")


def make_problem(n: int, j: int, *, seed: int = 0, missing: float = 0.1):
    """Rays to a smooth random motion from 4 cameras, and a Q ~ 3 temporal affinity (image order shuffled)."""
    g = np.random.default_rng(seed)
    t = np.arange(n) / 120.0
    base = g.normal(scale=0.3, size=(j, 3))
    X = base[None] + 0.2 * np.sin(2 * np.pi * (0.5 + g.uniform(size=(1, j, 3))) * t[:, None, None])
    cam = np.arange(n) % 4
    az = cam * np.pi / 2
    C = np.stack([3 * np.cos(az), 3 * np.sin(az), np.ones(n)], -1)
    r = X - C[:, None]
    r /= np.linalg.norm(r, axis=-1, keepdims=True)
    vis = g.uniform(size=(n, j)) >= missing
    A = np.zeros((n, n))
    idx = np.arange(n - 1)
    A[idx, idx + 1] = A[idx + 1, idx] = 1.0  # global time chain (different cameras)
    idx = np.arange(n - 4)
    A[idx, idx + 4] = 0.5  # within-stream link (same camera, next frame)
    perm = g.permutation(n)  # unsynchronised input: no useful image order
    return A[np.ix_(perm, perm)], C[perm], r[perm], vis[perm]


def _time(fn, repeats: int, device: torch.device) -> float:
    def once():
        if device.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize()
        return time.perf_counter() - t0

    once()
    return statistics.median(once() for _ in range(repeats))


def bench_size(
    n: int, j: int, device: torch.device, *, repeats: int, max_dense_gb: float
) -> dict[str, float | None]:
    """Seconds per solve for every method at size N (None where skipped)."""
    A_np, C, r, vis = make_problem(n, j)
    A = torch.tensor(A_np, dtype=torch.float64, device=device)
    methods = {
        "pinned-dense": lambda a: solve_structure(a, C, r, vis, method="dense"),
        "pinned-sparse": lambda a: solve_structure(a, C, r, vis, method="sparse"),
        "reference-3N": lambda a: solve_structure_dense(a, C, r, vis),
    }
    if device.type != "cpu":
        methods.pop("pinned-sparse")
    dense_gb = 3 * j * (3 * n) ** 2 * 8 / 1e9  # H, its repeat and the LU copy
    out: dict[str, float | None] = {}
    for name, fn in methods.items():
        if name == "reference-3N" and dense_gb > max_dense_gb:
            out[name] = out[name + " +bwd"] = None
            continue
        out[name] = _time(lambda fn=fn: fn(A), repeats, device)

        def fwd_bwd(fn=fn):
            a = A.clone().requires_grad_(True)
            fn(a).square().sum().backward()

        out[name + " +bwd"] = _time(fwd_bwd, repeats, device) if n <= 1000 else None
    return out


def main() -> None:
    """Parse arguments, run every size on CPU (and CUDA when present), print the tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 200, 300, 500, 1000])
    p.add_argument("--joints", type=int, default=31)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--max-dense-gb", type=float, default=6.0)
    p.add_argument("--devices", nargs="+", default=["cpu", "cuda"])
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    args = p.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for dev in args.devices:
        if dev == "cuda" and not torch.cuda.is_available():
            log.info("cuda: not available, skipped")
            continue
        device = torch.device(dev)
        log.info("\n%s (torch threads %d), J = %d, float64, seconds per solve (median of %d)", dev,
                 torch.get_num_threads(), args.joints, args.repeats)  # fmt: skip
        rows = [(n, bench_size(n, args.joints, device, repeats=args.repeats, max_dense_gb=args.max_dense_gb))
                for n in args.sizes]  # fmt: skip
        names = list(rows[0][1])
        log.info(
            "%6s " + " ".join(f"{k:>19s}" for k in names) + "   speed-up vs reference (fwd; fwd+bwd)", "N"
        )
        for n, res in rows:
            cells = " ".join(f"{res[k]:19.4f}" if res[k] is not None else f"{'skipped':>19s}" for k in names)
            ref, refb = res.get("reference-3N"), res.get("reference-3N +bwd")
            ratios = []
            for k in ("pinned-dense", "pinned-sparse"):
                if k in res and ref is not None:
                    ratios.append(f"{k}: {ref / res[k]:.1f}x; {refb / res[k + ' +bwd']:.1f}x")
            log.info("%6d %s   %s", n, cells, " | ".join(ratios) if ratios else "reference skipped")


if __name__ == "__main__":
    main()
