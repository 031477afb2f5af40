"""Benchmark of CPU threads: one reconstruction alone, then two side by side, per thread setting.

Run:  python benchmarks/bench_threads.py [--images 540] [--method dloe] [--settings default,1,cores]

Generates one capture of about ``--images`` images (the tiny recipe with 3 cameras at a higher rate over a
longer window) into ``--data`` (kept for the next run), then for each thread setting runs
``gttnet reconstruct SHARD --method METHOD --json`` as a fresh process, first alone and then two at once,
and prints wall times, the solver's own ``seconds`` and the slowdown of the pair against the lone run.
Settings: ``default`` (no --threads, no GTT_THREADS, no OMP_NUM_THREADS & co.: what a user gets),
``cores`` (``--threads`` = the machine's cores: what the libraries did on their own before ``--threads``),
or a number. Two commands that share a machine fairly take at most about twice as long as one alone on a
2-core machine; far more than that is oversubscription. The 1-minute load average is printed with each row:
on a machine that other jobs load, every number moves with it.
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

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gttdata.threads import THREAD_ENV_VARS, usable_cores  # noqa: E402

CAMERAS = 3  # the tiny recipe's ring


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in (*THREAD_ENV_VARS, "GTT_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))
    return env


def make_capture(data: Path, images: int) -> Path:
    """Generate (once) a tiny-recipe dataset whose test samples hold about ``images`` images."""
    shard = data / "test" / "shard-00000.h5"
    if shard.exists():
        return shard
    window_s = 6.0
    fps = max(1.0, images / (CAMERAS * window_s))
    cmd = [sys.executable, "-m", "gttdata", "generate", str(REPO / "recipes/gttdata/tiny.yaml"),
           f"capture.window_s={window_s}", f"capture.fps_hz={fps:g}",
           *(f"splits.{i}.sources.0.duration_s={window_s + 2}" for i in range(3)),
           "--out", str(data), "--no-progress", "--threads", "1"]  # fmt: skip
    subprocess.run(cmd, check=True, env=_env(), stdout=subprocess.DEVNULL, cwd=REPO)
    return shard


def _command(shard: Path, method: str, setting: str) -> list[str]:
    cmd = [sys.executable, "-m", "gttnet", "reconstruct", str(shard), "--method", method, "--json"]
    if setting == "cores":
        return [*cmd, "--threads", str(usable_cores())]
    return cmd if setting == "default" else [*cmd, "--threads", setting]


def run_together(cmds: list[list[str]]) -> list[tuple[float, float, int]]:
    """Start ``cmds`` at once; per command (wall s, solver s, images)."""
    t0 = time.perf_counter()
    procs = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=_env(),
                              cwd=REPO) for c in cmds]  # fmt: skip
    out = []
    for p in procs:
        stdout, _ = p.communicate()
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            raise SystemExit(f"bench_threads: {' '.join(p.args)} exited {p.returncode}")
        d = json.loads(stdout.strip().splitlines()[0])
        out.append((wall, float(d["seconds"]), int(d["n_images"])))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--images", type=int, default=540, help="About this many images per capture.")
    p.add_argument("--method", default="dloe")
    p.add_argument("--settings", default="default,1,cores", help="Comma-separated: default, cores or N.")
    p.add_argument("--repeats", type=int, default=1, help="Alone/pair rounds per setting (medians shown).")
    p.add_argument("--data", type=Path, default=Path("/tmp/gtt-bench-threads"))
    args = p.parse_args()
    shard = make_capture(args.data, args.images)
    print(f"{usable_cores()} cores; {args.method} on {shard}")
    print(
        "| threads | load | images | alone wall s | alone solve s | pair wall s (each) | pair solve s (each) "
        "| slowdown (solve) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for setting in args.settings.split(","):
        cmd = _command(shard, args.method, setting)
        alone, pair = [], []
        load = os.getloadavg()[0]
        for _ in range(args.repeats):
            alone += run_together([cmd])
            pair += run_together([cmd, cmd])
        a_wall, a_solve = statistics.median(r[0] for r in alone), statistics.median(r[1] for r in alone)
        p_wall, p_solve = statistics.median(r[0] for r in pair), statistics.median(r[1] for r in pair)
        print(f"| {setting} | {load:.1f} | {alone[0][2]} | {a_wall:.1f} | {a_solve:.2f} | {p_wall:.1f} | "
              f"{p_solve:.2f} | {p_solve / a_solve:.2f}x |")  # fmt: skip


if __name__ == "__main__":
    main()
