"""Benchmark of the k-d tree candidate search against the dense pairwise search (``none`` sequencing).

Run:  python benchmarks/bench_candidates.py [--window-s 12] [--n-seq 8] [--runs 3] [--dloe-kdtree]

Data: test samples of the paper recipe with a longer window (12 s = 1,440 images of 4 cameras at 30 Hz),
built in memory; samples where fewer than 90 % of the joints are observed (the subject leaves the
camera ring) are skipped, a choice made on the observations alone. For each search the table gives, as
medians over sequences (min..max in brackets):

* seconds of pseudo-triangulation + neighbourhoods (median of ``--runs`` runs per sequence);
* recall of the dense search's K = 20 neighbours (``vs dense``);
* recall of the true temporal neighbours: the share of an image's K neighbours that are among the K
  images of other cameras nearest to it in true time (ground truth used for scoring only);
* X_init error (MPJPE, mm) and GTT-Net's MPJPE (mm, bundled model) and seconds with that search
  (wall and CPU, each the median of ``--runs`` full ``reconstruct`` calls per sequence);
* the ratio of DLOE's seconds to GTT-Net's, both measured on the same sequences in this run, per
  sequence (wall and CPU seconds); ``--dloe-kdtree`` also times DLOE on the k-d tree candidates.

Fairness: both methods get the same observations through :func:`gttnet.methods.reconstruct` in the same
process, with BLAS and torch pinned to one thread; each timed call includes its own pseudo-triangulation
and order. The models are loaded (and every code path run once) before any timing, so no timed call
pays for loading a model.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from _table import fmt  # noqa: E402

import gttnet.geometry.candidates as cand_mod  # noqa: E402
from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.evaluate.metrics import mpjpe_mm  # noqa: E402
from gttnet.geometry.candidates import candidate_pseudo_triangulate  # noqa: E402
from gttnet.geometry.neighbours import neighbourhoods  # noqa: E402
from gttnet.geometry.triangulation import pseudo_triangulate  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402

K = 20


def true_neighbours(t: np.ndarray, cam: np.ndarray, k: int) -> np.ndarray:
    """The k other-camera images nearest in true time, shape ``(N, k)`` (ground truth: scoring only)."""
    order = np.argsort(t, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(t.size)
    out = np.empty((t.size, k), dtype=np.int64)
    w = 4 * k
    for i in range(t.size):
        lo, hi = max(rank[i] - w, 0), min(rank[i] + w + 1, t.size)
        win = order[lo:hi]
        win = win[cam[win] != cam[i]]
        out[i] = win[np.argsort(np.abs(t[win] - t[i]), kind="stable")[:k]]
    return out


def timed(runs: int, fn, *args, **kwargs):
    """``(last result, median wall s, median CPU s)`` of ``runs`` calls of ``fn(*args, **kwargs)``."""
    walls, cpus = [], []
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn(*args, **kwargs)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return out, statistics.median(walls), statistics.median(cpus)


def recall(found: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean([len(set(a[a >= 0]) & set(b)) / len(b) for a, b in zip(found, ref, strict=True)]))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    p.add_argument("--window-s", type=float, default=12.0)
    p.add_argument("--n-seq", type=int, default=8)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--no-dloe", action="store_true")
    p.add_argument("--dloe-kdtree", action="store_true", help="Also time DLOE on the k-d tree candidates.")
    p.add_argument(
        "--searches",
        default="all",
        help="Comma-separated subset of: dense, default, small, no-pose (or all).",
    )
    args = p.parse_args()
    torch.set_num_threads(1)
    recipe = load_recipe(args.recipe, [f"capture.window_s={args.window_s}"])
    all_searches = {
        "dense": ("dense", None),
        "default": ("kdtree (12 + pose 8, the default)", {"per_camera": 12, "pose_per_camera": 8}),
        "small": ("kdtree (8 + pose 8)", {"per_camera": 8, "pose_per_camera": 8}),
        "no-pose": ("kdtree (12, no pose round)", {"per_camera": 12, "pose_per_camera": 0}),
    }
    keys = list(all_searches) if args.searches == "all" else args.searches.split(",")
    if "dense" not in keys:
        keys.insert(0, "dense")  # the reference of the recall column
    searches = dict(all_searches[k] for k in keys)
    rows = {
        name: {k: [] for k in ("sec", "vs_dense", "temporal", "xinit", "gtt", "gtt_sec", "gtt_cpu")}
        for name in searches
    }
    dloe_cfgs = {"dense": "DLOE (dense, its default)"}
    if args.dloe_kdtree:
        dloe_cfgs["kdtree"] = "DLOE (kdtree candidates)"
    dloe = {c: {"sec": [], "cpu": [], "err": []} for c in dloe_cfgs}
    warm = False
    n_used = idx = 0
    while n_used < args.n_seq and idx < 10 * args.n_seq:
        sample = build_sample(recipe, "test", idx)[0]
        idx += 1
        obs, gt = make_view(sample, "none")
        if obs.visible.mean() < 0.9:
            continue
        n_used += 1
        C, r = obs.centers(), obs.rays()
        truth = true_neighbours(gt.timestamp_s, obs.cam_id, K)
        dense_nb = None
        for name, opts in searches.items():
            times = []
            for _ in range(args.runs):
                t0 = time.perf_counter()
                if opts is None:
                    pt = pseudo_triangulate(C, r, obs.visible, obs.cam_id)
                    nb = neighbourhoods(pt.cost, sequencing="none", cam_id=obs.cam_id, k=K, order=pt.order)
                else:
                    pt = candidate_pseudo_triangulate(C, r, obs.visible, obs.cam_id, **opts)
                    nb = pt.neighbours(K)
                times.append(time.perf_counter() - t0)
            if opts is None:
                dense_nb = nb
            row = rows[name]
            row["sec"].append(statistics.median(times))
            row["vs_dense"].append(recall(nb, dense_nb))
            row["temporal"].append(recall(nb, truth))
            row["xinit"].append(mpjpe_mm(pt.X_init, gt.points3d))
            # GTT-Net with this search: the k-d tree options are passed through prepare_inputs.
            orig = cand_mod.candidate_pseudo_triangulate
            if opts is not None:
                cand_mod.candidate_pseudo_triangulate = lambda *a, _o=opts, _f=orig, **kw: _f(
                    *a, **{**kw, **_o}
                )
            try:
                cand = "dense" if opts is None else "kdtree"
                if not warm:  # load this configuration's model before timing
                    reconstruct(obs, "gttnet", candidates=cand)
                rec, wall, cpu = timed(args.runs, reconstruct, obs, "gttnet", candidates=cand)
            finally:
                cand_mod.candidate_pseudo_triangulate = orig
            row["gtt"].append(mpjpe_mm(rec.points3d, gt.points3d))
            row["gtt_sec"].append(wall)
            row["gtt_cpu"].append(cpu)
        if not args.no_dloe:
            for c, d in dloe.items():
                rec, wall, cpu = timed(args.runs, reconstruct, obs, "dloe", candidates=c)
                d["sec"].append(wall)
                d["cpu"].append(cpu)
                d["err"].append(mpjpe_mm(rec.points3d, gt.points3d))
        warm = True
        print(f"sequence {idx - 1}: {obs.n_images} images done", flush=True)
    report(rows, dloe, dloe_cfgs, n_used, obs.n_images, no_dloe=args.no_dloe)


def report(rows: dict, dloe: dict, dloe_cfgs: dict, n_used: int, n_images: int, *, no_dloe: bool) -> None:
    """Print the search table and the DLOE / GTT-Net ratios."""
    print(f"\n{n_used} sequences of {n_images} images, none sequencing, K = {K}; median (min..max)")
    print(
        "| search | pseudo-tri + neighbours s | recall vs dense | temporal recall | X_init mm | GTT-Net mm "
        "| GTT-Net s | GTT-Net CPU s |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name, row in rows.items():
        print(
            f"| {name} | {fmt(row['sec'], '.3f')} | {fmt(row['vs_dense'])} | {fmt(row['temporal'])} | "
            f"{fmt(row['xinit'], '.1f')} | {fmt(row['gtt'], '.1f')} | {fmt(row['gtt_sec'], '.3f')} | "
            f"{fmt(row['gtt_cpu'], '.3f')} |"
        )
    if no_dloe:
        return
    print("\n| DLOE | MPJPE mm | s | CPU s |" + "".join(f" / GTT-Net {n} (wall; CPU) |" for n in rows))
    print("|---|---|---|---|" + "---|" * len(rows))
    for c, d in dloe.items():
        cells = []
        for row in rows.values():
            wall = [a / b for a, b in zip(d["sec"], row["gtt_sec"], strict=True)]
            cpu = [a / b for a, b in zip(d["cpu"], row["gtt_cpu"], strict=True)]
            cells.append(f" {fmt(wall, '.1f')}x; {fmt(cpu, '.1f')}x |")
        print(
            f"| {dloe_cfgs[c]} | {fmt(d['err'], '.1f')} | {fmt(d['sec'])} | {fmt(d['cpu'])} |"
            + "".join(cells)
        )
    print("(ratios: per sequence, each side the median of its runs; median (min..max) over sequences)")


if __name__ == "__main__":
    main()
