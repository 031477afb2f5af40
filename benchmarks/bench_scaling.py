"""Benchmark of reconstruction cost against recording length: seconds and peak memory, 300 to 72,000 images.

Run:  python benchmarks/bench_scaling.py [--sizes 300 1440 7200 24000 72000] [--runs 3] [--data DIR] [--drift-ppm X]
      [--configs NAME,...] [--stages NAME]

Data: ``recipes/gttdata/long.yaml`` (4 cameras at 30 Hz, one dancer inside the ring) with the capture
window set to ``size / 120`` seconds, generated once per size into ``--data`` (default
``/tmp/gtt-bench-scaling``, reused when present); ``--drift-ppm X`` draws every camera's clock
``uniform(-X, X)`` ppm off and starts the cameras up to 1 s apart at random sub-frame offsets, so the
windows must follow clocks recovered over the whole recording. Each configuration runs ``gttnet reconstruct`` end to
end in a fresh process (start-up, loading, reconstruction, report; ``--sequencing partial``):

* ``gttnet windowed``: GTT-Net window by window (``--window auto``: one piece up to 2,000 images);
* ``gttnet whole``: GTT-Net in one piece (``--window off``), up to ``--max-whole`` images;
* ``pseudo windowed``: pseudo-triangulation window by window;
* ``auto windowed``: the default method (clock recovery, then the high-pass prior) window by window;
* ``auto none windowed`` / ``auto none whole``: ``--sequencing none`` (no frame order at all): windows cut
  along the poses' own order (``gttnet.windowed.pose_times``) against the capture in one piece.

Stages (``--stages CONFIG``, default ``auto windowed``): the same reconstruction once more in a fresh
process that times its own steps in CPU seconds, as ``gttnet reconstruct --out result.h5`` runs them:
``read`` (the shard into observations), ``clocks`` (placing the images in time: the recording's clocks
under partial sequencing, the poses' order under none), ``windows`` (cutting sub-captures, stitching),
``solve`` (the windows' method calls), ``assess`` (the whole result's self-assessment) and ``write``
(the .h5 result); ``rest`` is the child's total CPU (start-up and imports included) minus those.

Wall and CPU seconds and peak RSS come from ``os.wait4`` on the child. The table gives medians over
``--runs`` runs (min..max), microseconds of wall time per image, that per-image cost as a ratio to the
smallest size's (1.0 = linear), and the whole / windowed wall-time ratio where both ran. On a machine
shared with other jobs wall time includes waiting for a core; CPU seconds do not.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _table import fmt

REPO = Path(__file__).resolve().parents[1]
RECIPE = REPO / "recipes" / "gttdata" / "long.yaml"
CONFIGS = {
    "gttnet windowed": ["--method", "gttnet", "--window", "auto"],
    "gttnet whole": ["--method", "gttnet", "--window", "off"],
    "pseudo windowed": ["--method", "pseudo", "--window", "auto"],
    "auto windowed": ["--method", "auto", "--window", "auto"],
    "auto none windowed": ["--sequencing", "none", "--method", "auto", "--window", "auto"],
    "auto none whole": ["--sequencing", "none", "--method", "auto", "--window", "off"],
}


def _env() -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    return env


def make_shard(size: int, root: Path, drift_ppm: float = 0.0) -> Path:
    """Generate (once) the long recipe cut to ``size`` images (clocks drifting by up to ``drift_ppm``)."""
    name = f"long_{size}" + (f"_drift{drift_ppm:g}" if drift_ppm else "")
    out = root / name
    shard = out / "test" / "shard-00000.h5"
    if shard.is_file() and (out / "manifest.json").is_file():
        return shard
    window = size / 120.0
    cmd = [
        sys.executable,
        "-m",
        "gttdata",
        "generate",
        str(RECIPE),
        f"capture.window_s={window}",
        f"splits.0.sources.0.duration_s={window + 1.0}",
        f"name={name}",
        *(
            [
                f"capture.drift_ppm={{uniform: [{-drift_ppm}, {drift_ppm}]}}",
                "capture.start_spread_s=1.0",
                "capture.stagger=random",
            ]
            if drift_ppm
            else []
        ),
        "--out",
        str(out),
        "--no-progress",
    ]
    subprocess.run(cmd, check=True, env=_env(), stdout=subprocess.DEVNULL)
    return shard


def run_child(cmd: list[str]) -> tuple[float, float, float, dict]:
    """Wall s, CPU s and peak RSS (MB) of one child process, and its JSON summary."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=_env())
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed with status {proc.returncode}")
    summary = json.loads(out.decode().strip().splitlines()[-1])
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, summary


def stages_of(shard: Path, config: list[str]) -> None:
    """Run one configuration in this process, timing its steps; print them as JSON (CPU seconds)."""
    import tempfile

    from gttnet.io import load_input
    from gttnet.io.recording_input import view_of_loaded
    from gttnet.methods import assessed
    from gttnet.recording import timing_options, write_outputs
    from gttnet.windowed import reconstruct_windowed

    opts = dict(zip(config[::2], config[1::2], strict=True))
    method, sequencing = opts["--method"], opts.get("--sequencing", "partial")
    window = opts.get("--window", "auto")
    c0 = time.process_time()
    loaded = load_input(shard, sequencing=sequencing)
    view = view_of_loaded(loaded)
    c1 = time.process_time()
    if window == "off":
        from gttnet.methods import reconstruct

        rec = reconstruct(view.observations, method, **timing_options(method, view))
    else:
        rec = reconstruct_windowed(
            view.observations,
            method,
            window=window if window == "auto" else int(window),
            **timing_options(method, view),
        )
    c2 = time.process_time()
    rec = assessed(rec, view.observations)
    c3 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:
        write_outputs(
            rec,
            view,
            [str(Path(tmp) / "result.h5")],
            None,
            image_index=loaded.image_index,
            source=loaded.source,
            recording_json="",
            trc={"up": "y", "filter": None, "names": None},
        )
    c4 = time.process_time()
    cpu = rec.info.get("cpu_seconds", {"clocks": 0.0, "solve": c2 - c1, "windows": 0.0})
    out = {"read": c1 - c0, **cpu, "assess": c3 - c2, "write": c4 - c3}
    print(json.dumps(out))


def run_stages(shard: Path, name: str) -> dict:
    """:func:`stages_of` in a fresh process: its stages and the whole child's CPU seconds (``total``)."""
    cmd = [sys.executable, __file__, "--stages-of", str(shard), "--stages", name]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=_env())
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed with status {status}")
    stages = json.loads(out.decode().strip().splitlines()[-1])
    total = usage.ru_utime + usage.ru_stime
    return {**stages, "rest": total - sum(stages.values()), "total": total, "wall": time.perf_counter() - t0}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[300, 1440, 7200, 24000, 72000])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--max-whole", type=int, default=3600, help="Largest size run in one piece.")
    p.add_argument("--configs", default=",".join(CONFIGS))
    p.add_argument("--data", type=Path, default=Path("/tmp/gtt-bench-scaling"))
    p.add_argument("--drift-ppm", type=float, default=0.0, help="Clock drift of the cameras, +- ppm.")
    p.add_argument(
        "--stages", default="auto windowed", help="Config whose steps are timed once per size ('' for none)."
    )
    p.add_argument("--stages-of", type=Path, default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.stages_of is not None:
        stages_of(args.stages_of, CONFIGS[args.stages])
        return
    rows = []
    stage_rows = []
    for size in args.sizes:
        shard = make_shard(size, args.data, args.drift_ppm)
        for name in args.configs.split(","):
            if name.endswith("whole") and size > args.max_whole:
                continue
            cmd = [
                sys.executable,
                "-m",
                "gttnet",
                "reconstruct",
                str(shard),
                *([] if "--sequencing" in CONFIGS[name] else ["--sequencing", "partial"]),
                *CONFIGS[name],
                "--json",
                "--no-progress",
            ]
            walls, cpus, rss, errs = [], [], [], []
            for _ in range(args.runs):
                wall, cpu, mb, summary = run_child(cmd)
                walls.append(wall)
                cpus.append(cpu)
                rss.append(mb)
                errs.append(summary.get("mpjpe_mm", float("nan")))
            rows.append((size, name, walls, cpus, rss, errs, summary.get("windows", 1)))
            print(f"{size} {name}: {statistics.median(walls):.1f} s", flush=True)
            if name == args.stages:
                stage_rows.append((size, run_stages(shard, name)))
    base = {}
    for size, name, walls, *_ in rows:
        base.setdefault(name, statistics.median(walls) / size)
    whole = {size: statistics.median(w) for size, name, w, *_ in rows if name == "gttnet whole"}
    drift = f", clocks drifting up to +-{args.drift_ppm:g} ppm" if args.drift_ppm else ""
    print(
        f"\n`gttnet reconstruct` end to end (--sequencing partial unless the config says none){drift}, "
        f"{args.runs} runs each, OMP_NUM_THREADS={_env()['OMP_NUM_THREADS']}; median (min..max)"
    )
    print(
        "| images | config | windows | wall s | CPU s | peak RSS MB | us/image | per-image vs smallest | whole / windowed | MPJPE mm |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for size, name, walls, cpus, rss, errs, windows in rows:
        med = statistics.median(walls)
        ratio = f"{whole[size] / med:.1f}x" if name == "gttnet windowed" and size in whole else "-"
        print(
            f"| {size:,} | {name} | {windows} | {fmt(walls, '.2f')} | {fmt(cpus, '.2f')} | {fmt(rss, '.0f')} | "
            f"{1e6 * med / size:.0f} | {med / size / base[name]:.2f} | {ratio} | {statistics.median(errs):.1f} |"
        )
    if stage_rows:
        keys = ("read", "clocks", "windows", "solve", "assess", "write", "rest")
        print(
            f"\nCPU seconds by step, `{args.stages}` (one run in a fresh process, one thread; rest: start-up, imports)"
        )
        print("| images | " + " | ".join(keys) + " | total CPU s |")
        print("|---|" + "---|" * (len(keys) + 1))
        for size, st in stage_rows:
            print(f"| {size:,} | " + " | ".join(f"{st[k]:.2f}" for k in keys) + f" | {st['total']:.2f} |")


if __name__ == "__main__":
    main()
