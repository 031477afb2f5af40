"""Alternatives to `sync`'s epipolar front end, measured on the same captures in the same run.

Run (development split; the numbers quoted in the README's "Synchronizing cameras after the fact"):
    python benchmarks/bench_sync_frontends.py --recipe recipes/gttdata/paper.yaml --split val --n-seq 5

Per sequence:
* ``partial``: `sync` (epipolar clock recovery, then HPF) against the DLOE front end of the issue's prototype:
  DLOE's recovered order, each camera's offset the median of (rank time - frame time) with rank time
  ``rank / (V * fps)`` (one uniform image rate), then the same HPF on those times.
* ``none``: DLOE alone against "DLOE's order sorted within each camera -> `sync` -> HPF" (the stretch item:
  how close `none` gets to `full`), and HPF on the true timestamps for reference.
CPU seconds of this process, one BLAS/torch thread; the first sequence's calls are repeated untimed first.
"""

from __future__ import annotations

import argparse
import os
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.capture.views import Observations, make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.baselines import reconstruct  # noqa: E402
from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm  # noqa: E402
from gttnet.geometry.ordering import stream_ranks  # noqa: E402
from gttnet.sync import Clocks, apply_clocks, clock_times  # noqa: E402

HPF = {"spacing": "time", "n_folds": 3, "search": "bracket"}  # what `sync` runs after its clocks


def dloe_front_end(obs: Observations, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """The prototype: DLOE order -> per-camera offset by median(rank time - frame time) -> HPF.

    Returns:
        ``(points3d in input order, recovered times)``.
    """
    d = reconstruct(obs, "dloe")
    cams = np.unique(obs.cam_id)
    rank_t = d.order / (fps * cams.size)
    tau = obs.stream_index / fps
    off = np.array([np.median(rank_t[obs.cam_id == c] - tau[obs.cam_id == c]) for c in cams])
    clocks = Clocks(cams, off, np.full(cams.size, fps), np.zeros(cams.size), np.full(cams.size, np.nan))
    t = clock_times(obs, clocks)
    rec = reconstruct(apply_clocks(obs, clocks), "hpf", **HPF)
    X = np.empty_like(rec.points3d)
    X[np.argsort(t, kind="stable")] = rec.points3d
    return X, t


def none_to_sync(obs: Observations) -> tuple[np.ndarray, float]:
    """``none``: DLOE's order, sorted within each camera as its stream order, then `sync`.

    Returns:
        ``(points3d in input order, the stream index recovered for each image)``.
    """
    d = reconstruct(obs, "dloe")
    si = stream_ranks(d.order, obs.cam_id)
    partial = Observations(
        sequencing="partial",
        skeleton=obs.skeleton,
        cam_id=obs.cam_id,
        K=obs.K,
        cam_from_world=obs.cam_from_world,
        keypoints_px=obs.keypoints_px,
        visible=obs.visible,
        image_size=obs.image_size,
        stream_index=si,
    )
    return reconstruct(partial, "sync").points3d, si


def _cpu(fn):
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--split", default="val")
    ap.add_argument("--n-seq", type=int, default=5)
    ap.add_argument("overrides", nargs="*")
    args = ap.parse_args()
    torch.set_num_threads(1)
    recipe = load_recipe(args.recipe, args.overrides)
    rows = []
    for i in range(args.n_seq):
        sample = build_sample(recipe, args.split, i)[0]
        fps = float(sample.meta["capture"]["fps_hz"][0])
        part, gt = make_view(sample, "partial")
        none, ngt = make_view(sample, "none")
        full, fgt = make_view(sample, "full")
        if i == 0:  # warm-up
            reconstruct(part, "sync")
            reconstruct(part, "dloe")
        s, t_s = _cpu(lambda part=part: reconstruct(part, "sync"))
        (Xd, _), t_d = _cpu(lambda part=part, fps=fps: dloe_front_end(part, fps))
        dn, t_dn = _cpu(lambda none=none: reconstruct(none, "dloe"))
        (Xn, si), t_n = _cpu(lambda none=none: none_to_sync(none))
        within = np.mean(
            [
                kendall_tau(si[none.cam_id == c], ngt.global_order[none.cam_id == c])
                for c in np.unique(none.cam_id)
            ]
        )
        row = {
            "sync": mpjpe_mm(s.points3d, gt.points3d),
            "dloe_front": mpjpe_mm(Xd, gt.points3d),
            "sync_s": t_s,
            "dloe_front_s": t_d,
            "dloe_none": mpjpe_mm(dn.points3d, ngt.points3d),
            "none_sync": mpjpe_mm(Xn, ngt.points3d),
            "within_cam_tau": within,
            "dloe_none_s": t_dn,
            "none_sync_s": t_n,
            "hpf_full": mpjpe_mm(reconstruct(full, "hpf").points3d, fgt.points3d),
        }
        rows.append(row)
        print(i, sample.motion_name, {k: round(v, 3) for k, v in row.items()}, flush=True)
    a = {k: np.array([r[k] for r in rows]) for k in rows[0]}
    print()
    print("| condition | method | MPJPE mm mean / median | CPU s median |")
    print("|---|---|---|---|")
    for cond, key, label in [
        ("partial", "sync", "`sync` (epipolar front end)"),
        ("partial", "dloe_front", "DLOE front end (prototype) + HPF"),
        ("none", "dloe_none", "DLOE"),
        ("none", "none_sync", "DLOE order within cameras -> `sync`"),
    ]:
        print(
            f"| {cond} | {label} | {a[key].mean():.2f} / {np.median(a[key]):.2f} | {np.median(a[key + '_s']):.2f} |"
        )
    print(
        f"| full | HPF (true timestamps) | {a['hpf_full'].mean():.2f} / {np.median(a['hpf_full']):.2f} | - |"
    )
    print(
        f"\nmean within-camera Kendall tau of DLOE's order against the true order (none): {np.round(a['within_cam_tau'], 3).tolist()}"
    )


if __name__ == "__main__":
    main()
