"""Out-of-distribution benchmark of ``auto`` and of the self-assessment (``quality``) it selects with.

Run (the test half is only reported, never tuned on):
    python benchmarks/bench_auto.py --split test --n-seq 3
    python benchmarks/bench_auto.py --split val --n-seq 2 --cells walk_1px_drop30,quadruped
    python benchmarks/bench_auto.py --rows runs/bench_auto/test.jsonl --table   # re-print from saved rows
    python benchmarks/bench_auto.py --recipes recipes/gttdata/paper.yaml,recipes/gttdata/default.yaml \
        --split val --n-seq 8 --no-auto --rows runs/bench_auto/fit.jsonl       # calibration captures
    python benchmarks/bench_auto.py --fit runs/bench_auto/fit.jsonl --check runs/bench_auto/test.jsonl

Cells are the recipes under ``recipes/gttdata/ood/`` (periodic walks with 30 % missing joints at 1 and 5 px,
25/50/60 Hz and mixed rates, non-uniform timestamps, far cameras, pan-tilt-zoom cameras, a quadruped, one
camera declared with a wrong frame rate, a blind camera, a second person in some frames, a quadruped turning
at 10 Hz, fast for the rate: ``fast_10hz``); captures are built in memory (``gttdata.generate_plan.build_sample``, ~300 images each).
Per capture and sequencing condition every candidate method runs (``gttnet.auto.candidates`` for that
condition, order-free methods included), then ``auto`` itself. Per cell it prints each method's mean MPJPE,
auto's picks, auto's regret (its MPJPE over the best method's on the same capture and condition: the best
method runnable with that much sequencing or less), the self-assessment's ``expected_error_mm`` against the
truth (fraction within [0.5x, 2x]) and auto's time over the fastest candidate within 5 % of the best
(``NEAR_BEST``). A method that leaves images without a pose (a camera without a clock) is scored on the
images it reconstructs; its rows say which share (``reconstructed``).
Pan-tilt-zoom cameras (a camera pose per image) are the `ptz` cell (the generator's `capture.ptz_prob`).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.capture.views import make_view  # noqa: E402
from gttdata.generate_plan import build_sample  # noqa: E402
from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.evaluate.metrics import mpjpe_mm  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402
from gttnet.quality import CALIBRATION, EXTRAS, FEATURES, ROUGHNESS_FLOOR, features, predict_mm  # noqa: E402

OOD = Path(__file__).resolve().parents[1] / "recipes" / "gttdata" / "ood"
#: Per-cell changes to the observations: a camera declared with a wrong frame rate ({camera: declared Hz};
#: the other cameras are declared at their true rate), a camera that sees nothing.
CELL_FPS: dict[str, dict[int, float]] = {"wrong_rate": {1: 30.0}}
CELL_BLIND = {"blind_camera": 0}
#: A second person walking through some cameras' views: in a contiguous ``fraction`` of those cameras'
#: frames the detector hands in that person (``offset_m`` beside the subject, moving as the subject does
#: in reverse time: another pose at every moment) instead of the subject, as a one-person reader would.
CELL_SECOND = {"second_person": {"cameras": (2, 3), "fraction": 0.2, "offset_m": 1.2, "start": 0.4}}
SEQS = ("none", "partial", "full")
#: auto's time is compared with the fastest candidate whose MPJPE is within this factor of the best's.
NEAR_BEST = 1.05
#: Multiples of the per-point uncertainty (over its interval factor) at which the coverage is recorded.
COVER_AT = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0)


def _coverage(rec, gt) -> dict:
    """Fraction of the points whose true 3-D error is within k x the stated uncertainty, for k in COVER_AT."""
    from gttnet.quality import CALIBRATION

    if rec.uncertainty_mm is None:
        return {}
    err = 1000.0 * np.linalg.norm(rec.points3d - gt.points3d, axis=-1)
    unc = rec.uncertainty_mm / float(CALIBRATION["interval_factor"])
    ok = np.isfinite(err) & np.isfinite(unc)
    return {
        "covered": float(np.mean(err[ok] <= rec.uncertainty_mm[ok])),
        "cover_at": [round(float(np.mean(err[ok] <= k * unc[ok])), 4) for k in COVER_AT],
    }


def _score(rec, gt) -> dict:
    """``mpjpe_mm`` over the points ``rec`` reconstructs, and ``reconstructed`` (their share) where not all.

    A camera whose clock cannot be recovered (a blind camera) is left out by the clock-recovering methods:
    its images' poses are NaN, and their MPJPE is over the other images.
    """
    ok = np.isfinite(rec.points3d).all(axis=-1)
    if ok.all():
        return {"mpjpe_mm": mpjpe_mm(rec.points3d, gt.points3d)}
    err = 1000.0 * np.linalg.norm(rec.points3d - gt.points3d, axis=-1)
    return {
        "mpjpe_mm": float(err[ok].mean()) if ok.any() else float("nan"),
        "reconstructed": float(ok.mean()),
    }


def _second_person(obs, gt, sample, *, cameras, fraction: float, offset_m: float, start: float):
    """``obs`` with a second person's detections in place of the subject's in some frames of ``cameras``.

    The second person is the subject's motion in reverse time, ``offset_m`` to the side (world x), projected
    through each image's camera with the capture's 2-D noise; in each camera of ``cameras`` it replaces the
    subject in the frames from ``start`` to ``start + fraction`` of the camera's frames (by time).
    """
    X = np.asarray(gt.points3d, dtype=np.float64)
    order = np.argsort(gt.timestamp_s, kind="stable")
    other = np.empty_like(X)
    other[order] = X[order[::-1]]  # the pose of the mirrored moment
    other = other + np.array([offset_m, 0.0, 0.0])
    T = np.asarray(obs.cam_from_world, dtype=np.float64)
    Xc = np.einsum("nab,njb->nja", T[:, :3, :3], other) + T[:, None, :3, 3]
    uv = np.einsum("nab,njb->nja", np.asarray(obs.K)[:, :2, :3], Xc) / Xc[..., 2:3]
    sigma = float(sample.meta["capture"]["sigma_px"])
    uv = uv + np.random.default_rng(7).normal(0.0, sigma, uv.shape)
    kp, vis = np.asarray(obs.keypoints_px).copy(), np.asarray(obs.visible).copy()
    t = np.asarray(gt.timestamp_s)
    for c in cameras:
        idx = np.flatnonzero(np.asarray(obs.cam_id) == c)
        idx = idx[np.argsort(t[idx], kind="stable")]
        lo = int(start * idx.size)
        swap = idx[lo : lo + int(fraction * idx.size)]
        seen = Xc[swap, :, 2] > 0
        kp[swap] = np.where(seen[..., None], uv[swap], np.nan)
        vis[swap] = seen
    return replace(obs, keypoints_px=kp, visible=vis)


def _cell_view(sample, seq: str, cell: str):
    """The capture's view under ``seq`` with the cell's input faults applied, and timing options."""
    obs, gt = make_view(sample, seq)
    opts: dict = {}
    if cell in CELL_BLIND:
        blind = obs.cam_id == CELL_BLIND[cell]
        vis = obs.visible.copy()
        vis[blind] = False
        kp = obs.keypoints_px.copy()
        kp[blind] = np.nan
        obs = replace(obs, visible=vis, keypoints_px=kp)
    if cell in CELL_SECOND:
        obs = _second_person(obs, gt, sample, **CELL_SECOND[cell])
    if cell in CELL_FPS:
        true_hz = np.asarray(sample.meta["capture"]["fps_hz"], dtype=np.float64)
        hz = true_hz.copy()
        for c, declared in CELL_FPS[cell].items():
            hz[c] = declared
        if obs.stream_time_s is not None:  # each camera's clock counts frames at its declared rate
            cam = np.asarray(obs.cam_id)
            obs = replace(obs, stream_time_s=np.asarray(obs.stream_time_s) * true_hz[cam] / hz[cam])
        opts["fps"] = {int(c): float(r) for c, r in enumerate(hz)}
    if obs.stream_time_s is not None:
        opts["frame_times_s"] = np.asarray(obs.stream_time_s, dtype=np.float64)
    return obs, gt, opts


def _true_mm(r: dict) -> float:
    """The error ``expected_error_mm`` predicts: over the returned points.

    Rows written before :func:`_score` carry it as ``mpjpe_finite_mm`` beside a ``nan_fraction``.
    """
    return float(r.get("mpjpe_finite_mm", r["mpjpe_mm"])) if r.get("nan_fraction") else float(r["mpjpe_mm"])


def _scalar(v):
    return None if v is None or not np.isfinite(v) else round(float(v), 4)


def run_capture(sample, cell: str, *, with_auto: bool = True, seqs=SEQS) -> list[dict]:
    """One row per (sequencing, method) of one capture; ``auto`` rows name the pick and the candidates."""
    from gttnet.auto import candidates

    rows = []
    for seq in seqs:
        obs, gt, timing = _cell_view(sample, seq, cell)
        for name, options in candidates(obs, **timing):
            t0 = time.perf_counter()
            try:
                rec = reconstruct(obs, name, **options)
            except Exception as exc:  # a candidate that cannot run on this input (reported, not fatal)
                rows.append(
                    {
                        "cell": cell,
                        "capture": sample.name,
                        "sequencing": seq,
                        "method": name,
                        "error": str(exc).split("\n")[0],
                    }
                )
                continue
            sec = time.perf_counter() - t0
            f = features(obs, rec)
            row = {
                "cell": cell,
                "capture": sample.name,
                "sequencing": seq,
                "method": name,
                **_score(rec, gt),
                "seconds": sec,
                "expected_error_mm": rec.info.get("quality", {}).get("expected_error_mm"),
            }
            row.update(_coverage(rec, gt))
            row.update({k: _scalar(f[k]) for k in (*EXTRAS, *FEATURES)})
            rows.append(row)
            print(json.dumps(row), flush=True)
        if with_auto:
            t0 = time.perf_counter()
            rec = reconstruct(obs, "auto", **timing)
            row = {
                "cell": cell,
                "capture": sample.name,
                "sequencing": seq,
                "method": "auto",
                **_score(rec, gt),
                "seconds": time.perf_counter() - t0,
                "expected_error_mm": rec.info.get("quality", {}).get("expected_error_mm"),
                "auto": rec.info.get("auto"),
            }
            row.update(_coverage(rec, gt))
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def collect(recipes: list[tuple[str, str]], split: str, n_seq: int, with_auto: bool, seqs=SEQS) -> list[dict]:
    """Rows of every capture of every (cell, recipe path)."""
    rows = []
    for cell, path in recipes:
        recipe = load_recipe(path, [])
        for i in range(n_seq):
            sample = build_sample(recipe, split, i)[0]
            rows += run_capture(sample, cell, with_auto=with_auto, seqs=seqs)
    return rows


def _ratio_ok(pred, true) -> bool:
    return pred is not None and 0.5 * pred <= true <= 2.0 * pred


def table(rows: list[dict]) -> str:
    """Per cell and sequencing: methods' mean MPJPE, auto's picks, regret, calibration, cost."""
    ok_rows = [r for r in rows if "mpjpe_mm" in r]
    out = [
        "| cell | seq | methods: mean MPJPE mm | auto mm | auto picks | regret mean / max | "
        "quality within [0.5x, 2x] | auto s / best method's s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    regrets, calib, costs = [], [], []
    for cell in dict.fromkeys(r["cell"] for r in ok_rows):
        for seq in SEQS:
            sel = [r for r in ok_rows if r["cell"] == cell and r["sequencing"] == seq]
            if not sel:
                continue
            methods = [m for m in dict.fromkeys(r["method"] for r in sel) if m != "auto"]
            means = {m: np.mean([r["mpjpe_mm"] for r in sel if r["method"] == m]) for m in methods}
            reg, cal, cost, picks = [], [], [], []
            for cap in dict.fromkeys(r["capture"] for r in sel):
                cr = {r["method"]: r for r in sel if r["capture"] == cap}
                cands = [cr[m] for m in methods if m in cr]
                best = min(c["mpjpe_mm"] for c in cands)
                cal += [_ratio_ok(c["expected_error_mm"], _true_mm(c)) for c in cands]
                if "auto" in cr:
                    a = cr["auto"]
                    reg.append(a["mpjpe_mm"] / best)
                    cal.append(_ratio_ok(a["expected_error_mm"], _true_mm(a)))
                    picks.append((a.get("auto") or {}).get("ran", "?"))
                    near = [c for c in cands if c["mpjpe_mm"] <= NEAR_BEST * best]  # as good as the best
                    cost.append(a["seconds"] / min(c["seconds"] for c in near))
            regrets += reg
            calib += cal
            costs += cost
            ms = ", ".join(f"{m} {v:.1f}" for m, v in means.items())
            am = np.mean([r["mpjpe_mm"] for r in sel if r["method"] == "auto"]) if reg else float("nan")
            pk = ", ".join(f"{p}×{picks.count(p)}" for p in dict.fromkeys(picks))
            rg = f"{np.mean(reg):.3f} / {np.max(reg):.3f}" if reg else "-"
            cs = f"{np.median(cost):.2f}" if cost else "-"
            out.append(f"| {cell} | {seq} | {ms} | {am:.1f} | {pk} | {rg} | {np.mean(cal):.0%} | {cs} |")
    left = len(regrets)
    regrets = [g for g in regrets if np.isfinite(g)]  # auto or the best left points NaN (no clock)
    if regrets:
        out.append(
            f"\nauto regret: median {np.median(regrets):.3f}, max {np.max(regrets):.3f}, "
            f"{np.mean(np.asarray(regrets) <= 1.10):.0%} of {len(regrets)} captures <= 1.10 ({left - len(regrets)} "
            f"left out: NaN points); cost median "
            f"{np.median(costs):.2f}x, max {np.max(costs):.2f}x the best method's time"
        )
        out.append(_no_regression(ok_rows))
    if calib:
        out.append(
            f"quality: true MPJPE within [0.5x, 2x] of expected_error_mm in {np.mean(calib):.1%} "
            f"of {len(calib)} reconstructions"
        )
        out.append(_coverage_line(ok_rows))
        out.append("\n" + calibration_table(ok_rows))
    return "\n".join(out)


def calibration_table(rows: list[dict]) -> str:
    """Per cell: the share within [0.5x, 2x], without and with the weak and outlier terms, and the coverage.

    "without" recomputes each candidate's prediction from its row with ``weak_fraction`` and
    ``outlier_fraction`` set to 0 (the model before those terms); auto's rows carry no evidence, so the
    first two columns are over the candidates only.
    """
    out = [
        "| cell | candidates (+ auto) | within [0.5x, 2x] without weak/outlier terms | with | with, auto's rows "
        "included | per-point coverage mean / median |",
        "|---|---|---|---|---|---|",
    ]
    for cell in [*dict.fromkeys(r["cell"] for r in rows), "all"]:
        sel = rows if cell == "all" else [r for r in rows if r["cell"] == cell]
        cand = [r for r in sel if r["method"] != "auto" and "noise_mm" in r]
        if not cand:
            continue
        before = [
            _ratio_ok(predict_mm({**r, "weak_fraction": 0.0, "outlier_fraction": 0.0}), _true_mm(r))
            for r in cand
        ]
        after = [_ratio_ok(r["expected_error_mm"], _true_mm(r)) for r in cand]
        both = [_ratio_ok(r["expected_error_mm"], _true_mm(r)) for r in sel]
        cov = [r["covered"] for r in sel if "covered" in r]
        out.append(
            f"| {cell} | {len(cand)} (+{len(sel) - len(cand)}) | {np.mean(before):.1%} | {np.mean(after):.1%} | "
            f"{np.mean(both):.1%} | {np.mean(cov):.1%} / {np.median(cov):.1%} |"
        )
    return "\n".join(out)


def _derived(r: dict) -> dict:
    """The ratios of :data:`gttnet.quality.FEATURES` and ``excess_mm`` from a row's raw evidence."""
    n = r["noise_mm"]
    s = max(r["sigma_px"] or r["residual_px"], 0.1)
    r.setdefault("holdout_ratio", r["holdout_mm"] / n)
    r.setdefault("roughness_ratio", r["roughness_mm"] / n + ROUGHNESS_FLOOR)
    r.setdefault("excess_mm", float(np.sqrt(max(r["residual_px"] ** 2 - s**2, 0.0)) * n / s))
    return r


def _no_regression(rows: list[dict]) -> str:
    """Auto given each camera's frame order against HPF given the true timestamps, same captures."""
    ratios = []
    for cell, cap in dict.fromkeys((r["cell"], r["capture"]) for r in rows):
        a = [
            r
            for r in rows
            if (r["cell"], r["capture"], r["sequencing"], r["method"]) == (cell, cap, "partial", "auto")
        ]
        h = [
            r
            for r in rows
            if (r["cell"], r["capture"], r["sequencing"], r["method"]) == (cell, cap, "full", "hpf")
        ]
        if a and h:
            ratios.append(a[0]["mpjpe_mm"] / h[0]["mpjpe_mm"])
    ratios = [x for x in ratios if np.isfinite(x)]  # auto left points NaN (a camera without a clock)
    if not ratios:
        return ""
    return (
        f"auto with each camera's frame order / HPF with true timestamps: median {np.median(ratios):.3f}, "
        f"{np.mean(np.asarray(ratios) <= 1.05):.0%} of {len(ratios)} captures <= 1.05"
    )


def _coverage_line(rows: list[dict]) -> str:
    """Mean per-point coverage of the stated uncertainty (its rate is ``interval_rate``)."""
    from gttnet.quality import CALIBRATION

    cov = [r["covered"] for r in rows if "covered" in r]
    if not cov:
        return ""
    return (
        f"per-point uncertainty: covers the true 3-D error in {np.mean(cov):.1%} of points (mean over "
        f"{len(cov)} reconstructions; stated rate {CALIBRATION['interval_rate']:.0%}), median "
        f"{np.median(cov):.1%}"
    )


def fit(rows: list[dict]) -> dict:
    """Least-squares fit of log MPJPE on the logs of :data:`gttnet.quality.FEATURES`, and the weak gap factor.

    Only reconstructions whose residual is within the noise (``excess_mm`` at most half the noise at the
    joints' depth), without blind images, with at most 1 % weakly observed points and 2 % contradicted images
    enter the log-linear fit: the excess, blind, weak and outlier terms have their own forms.
    ``weak_gap_factor`` and ``outlier_factor`` are then chosen together on the other reconstructions (a grid,
    least squares in log), with :data:`gttnet.quality.CALIBRATION`'s intercept and slopes (so they can be
    refitted alone).
    """
    use = [_derived(r) for r in rows if "mpjpe_mm" in r and r["method"] != "auto" and r.get("noise_mm")]
    special = [r for r in use if _weak_or_outlier(r)]
    use = [r for r in use if r["excess_mm"] <= 0.5 * r["noise_mm"] and not r.get("blind_fraction")]
    use = [r for r in use if not _weak_or_outlier(r)]
    A = np.array([[1.0] + [np.log(r[k]) for k in FEATURES] for r in use])
    y = np.log([r["mpjpe_mm"] for r in use])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    print(
        f"# fit on {len(use)} reconstructions: residual std {resid.std():.3f} (log), "
        f"{np.mean(np.abs(resid) <= np.log(2)):.1%} within [0.5x, 2x]",
        file=sys.stderr,
    )
    out = {"intercept": round(float(coef[0]), 4), "slopes": [round(float(c), 4) for c in coef[1:]]}
    if special:  # the weak and outlier factors, under the module's current log-linear part
        grid = np.round(np.arange(0.0, 3.01, 0.1), 2)
        best = (np.inf, 0.0, 0.0)
        for cw in grid:
            for co in grid:
                cal = {**CALIBRATION, "weak_gap_factor": cw, "outlier_factor": co}
                cost = float(
                    np.mean([np.log(r["mpjpe_mm"] / max(predict_mm(r, cal), 1e-6)) ** 2 for r in special])
                )
                best = min(best, (cost, float(cw), float(co)))
        out["weak_gap_factor"], out["outlier_factor"] = best[1], best[2]
        cal = {**CALIBRATION, "weak_gap_factor": best[1], "outlier_factor": best[2]}
        ok = np.mean([_ratio_ok(predict_mm(r, cal), r["mpjpe_mm"]) for r in special])
        print(
            f"# weak / outlier factors on {len(special)} reconstructions: {best[1]}, {best[2]} "
            f"(log residual rms {np.sqrt(best[0]):.3f}, {ok:.1%} within [0.5x, 2x])",
            file=sys.stderr,
        )
    return out


def _weak_or_outlier(r: dict) -> bool:
    """Whether a row has over 1 % weakly observed points or over 2 % contradicted images."""
    return (r.get("weak_fraction") or 0.0) > 0.01 or (r.get("outlier_fraction") or 0.0) > 0.02


def main() -> None:
    """Command line: see the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", default="", help="comma-separated cell names (default: every ood recipe)")
    ap.add_argument("--recipes", default="", help="comma-separated recipe paths instead of the cells")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n-seq", type=int, default=3, help="captures per cell")
    ap.add_argument("--no-auto", action="store_true", help="candidates only (calibration captures)")
    ap.add_argument("--seqs", default=",".join(SEQS), help="comma-separated sequencing conditions to run")
    ap.add_argument("--rows", default="", help="JSONL file: written after a run, read with --table (a,b,...)")
    ap.add_argument("--table", action="store_true", help="print the table of --rows without running")
    ap.add_argument("--fit", default="", help="fit the calibration on this JSONL and print it")
    ap.add_argument("--check", default="", help="with --fit: the fraction within [0.5x, 2x] on this JSONL")
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.fit:
        cal = fit([json.loads(x) for x in Path(args.fit).read_text().splitlines()])
        print(json.dumps(cal))
        return
    if args.table:  # several files may be given, comma-separated; lines that are not JSON rows are skipped
        lines = [x for p in args.rows.split(",") for x in Path(p).read_text().splitlines()]
        print(table([json.loads(x) for x in lines if x.startswith("{")]))
        return
    if args.recipes:
        recipes = [(Path(p).stem, p) for p in args.recipes.split(",")]
    else:
        names = args.cells.split(",") if args.cells else sorted(p.stem for p in OOD.glob("*.yaml"))
        recipes = [(c, str(OOD / f"{c}.yaml")) for c in names]
    rows = collect(recipes, args.split, args.n_seq, not args.no_auto, tuple(args.seqs.split(",")))
    if args.rows:
        Path(args.rows).parent.mkdir(parents=True, exist_ok=True)
        Path(args.rows).write_text("".join(json.dumps(r) + "\n" for r in rows))
    print()
    print(table(rows))


if __name__ == "__main__":
    main()
