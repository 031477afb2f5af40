"""Benchmark of CLI start-up: wall time of ``gttnet --help`` and ``gttdata --help`` in fresh interpreters.

Run:  python benchmarks/bench_startup.py [--runs 15]

Each command runs ``--runs`` times as a subprocess (``python -m <package> --help``, the same interpreter as
this script); the table shows the median, the spread (min..max) and the ratio to a bare ``python -c pass``
measured in the same run, so a loaded machine shifts every row alike, and the child's CPU seconds (which
waiting for a core does not inflate). ``--console-scripts`` also times the
installed entry points found on PATH (which import the installed checkout, not necessarily this one).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _time(cmd: list[str], runs: int, env: dict) -> list[tuple[float, float]]:
    """``(wall s, CPU s)`` of each run; CPU from ``os.wait4`` (user + system of the child)."""
    out = []
    for _ in range(runs):
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed")
        out.append((time.perf_counter() - t0, usage.ru_utime + usage.ru_stime))
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=15)
    p.add_argument("--console-scripts", action="store_true", help="Also time gttnet/gttdata found on PATH.")
    p.add_argument("--torch-runs", type=int, default=3, help="Runs of 'import torch' (for scale; slow).")
    args = p.parse_args()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    py = sys.executable
    cases = {
        "python -c pass (baseline)": [py, "-c", "pass"],
        "gttnet --help": [py, "-m", "gttnet", "--help"],
        "gttdata --help": [py, "-m", "gttdata", "--help"],
        "gttnet reconstruct --help": [py, "-m", "gttnet", "reconstruct", "--help"],
        "gttnet sync --help": [py, "-m", "gttnet", "sync", "--help"],
        "gttnet train --help": [py, "-m", "gttnet", "train", "--help"],
        "gttdata generate --help": [py, "-m", "gttdata", "generate", "--help"],
        "import the DLOE method (no torch)": [
            py,
            "-c",
            "from gttnet.methods import method_spec; method_spec('dloe')",
        ],
    }
    if args.console_scripts:
        for name in ("gttnet", "gttdata"):
            exe = shutil.which(name)
            if exe:
                cases[f"{exe} --help"] = [exe, "--help"]
    rows = []
    for name, cmd in cases.items():
        _time(cmd, 1, env)  # warm the file cache
        rows.append((name, _time(cmd, args.runs, env)))
    if args.torch_runs > 0:
        rows.append(("import torch (for scale)", _time([py, "-c", "import torch"], args.torch_runs, env)))
    base = statistics.median(w for w, _ in rows[0][1])
    print(f"{args.runs} runs each ({args.torch_runs} of import torch)")
    print("| command | median s | min..max s | vs bare python | CPU s (median) |")
    print("|---|---|---|---|---|")
    for name, runs in rows:
        t = [w for w, _ in runs]
        med = statistics.median(t)
        cpu = statistics.median(c for _, c in runs)
        print(f"| `{name}` | {med:.3f} | {min(t):.3f}..{max(t):.3f} | {med / base:.1f}x | {cpu:.3f} |")


if __name__ == "__main__":
    main()
