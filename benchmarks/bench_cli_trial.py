"""Benchmark of a whole CLI trial: ``gttnet reconstruct RECORDING`` on a 400-image recording, start to exit.

Run:  python benchmarks/bench_cli_trial.py [--runs 5] [--images 400] [--methods auto dloe pseudo] [--data DIR]
      [--no-split]

Data: ``recipes/gttdata/long.yaml`` (4 cameras at 30 Hz, one dancer) cut to ``--images`` images, generated
once into ``--data`` (default ``/tmp/gtt-bench-cli-trial``) and written as a real recording by
``gttdata export`` (OpenPose folders, per-camera timestamp CSVs, calibration, ``project.toml``). Each method
then runs as a user would type it, ``gttnet reconstruct DATA/recording/project.toml --method M --json``, in a
fresh process: start-up, reading the detector files, the reconstruction and the report (scored against the
export's ground truth). ``python -c pass`` and ``python -c "import numpy, scipy.sparse"`` run beside them
as baselines. Wall and CPU seconds and peak RSS come from ``os.wait4`` on the child; one BLAS/OpenMP thread
(``OMP_NUM_THREADS=1`` ...) unless the environment says otherwise. On a machine shared with other jobs wall
time includes waiting for a core; CPU seconds do not.

A second table splits each method's CPU seconds: a fresh process runs the same command twice through
``gttnet.cli.main`` (``--split``, default on): the first run pays the imports and first uses, the second is
the work alone (reading the detector files, the method, the self-assessment, the report); ``interpreter +
CLI`` is ``gttnet reconstruct --help``'s CPU time, and ``import numpy + SciPy`` that of importing the SciPy
modules the classical methods use (sparse, linalg, optimize), the floor under any run that needs them.
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


def _env() -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env.setdefault(var, "1")
    return env


def make_recording(images: int, root: Path) -> Path:
    """Generate (once) the long recipe cut to ``images`` images and export it as a recording; its project file."""
    out = root / f"long_{images}"
    project = out / "recording" / "project.toml"
    if project.is_file():
        return project
    window = images / 120.0
    py = [sys.executable, "-m"]
    gen = [*py, "gttdata", "generate", str(RECIPE), f"capture.window_s={window}",
           f"splits.0.sources.0.duration_s={window + 1.0}", f"name=long_{images}", "--out", str(out / "data"),
           "--no-progress", "--overwrite"]  # fmt: skip
    subprocess.run(gen, check=True, env=_env(), stdout=subprocess.DEVNULL)
    export = [*py, "gttdata", "export", str(out / "data"), "--out", str(out / "recording"), "--overwrite"]
    subprocess.run(export, check=True, env=_env(), stdout=subprocess.DEVNULL)
    return project


def run_child(cmd: list[str]) -> tuple[float, float, float, str]:
    """Wall s, CPU s and peak RSS (MB) of one child process, and its last line of output."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=_env())
    assert proc.stdout is not None
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed with status {code}")
    lines = out.decode().strip().splitlines()
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0, lines[-1] if lines else ""


def split_of(args: list[str]) -> None:
    """Run ``gttnet`` with ``args`` twice in this process; print both runs' CPU seconds as JSON."""
    import contextlib
    import io

    from gttnet.cli import main as cli

    cpu = []
    for _ in range(2):
        c0 = time.process_time()
        with contextlib.redirect_stdout(io.StringIO()):
            cli.main(args, standalone_mode=False)
        cpu.append(time.process_time() - c0)
    print(json.dumps({"first": cpu[0], "second": cpu[1]}))


def run_split(args: list[str]) -> dict:
    """:func:`split_of` in a fresh process."""
    cmd = [sys.executable, __file__, "--split-of", *args]
    out = subprocess.run(cmd, check=True, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    return json.loads(out.stdout.decode().strip().splitlines()[-1])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--split-of":
        split_of(sys.argv[2:])
        return
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--images", type=int, default=400)
    p.add_argument("--methods", nargs="+", default=["auto", "dloe", "pseudo"])
    p.add_argument("--data", type=Path, default=Path("/tmp/gtt-bench-cli-trial"))
    p.add_argument(
        "--split", action=argparse.BooleanOptionalAction, default=True, help="The CPU split table."
    )
    args = p.parse_args()
    project = make_recording(args.images, args.data)
    py = sys.executable
    cases: dict[str, list[str]] = {
        "python -c pass (baseline)": [py, "-c", "pass"],
        "python -c 'import numpy, scipy.sparse' (baseline)": [py, "-c", "import numpy, scipy.sparse"],
        "python -c 'import numpy, scipy.sparse, scipy.linalg, scipy.optimize' (baseline)": [
            py, "-c", "import numpy, scipy.sparse, scipy.linalg, scipy.optimize",
        ],
        "gttnet reconstruct --help": [py, "-m", "gttnet", "reconstruct", "--help"],
    }  # fmt: skip
    for m in args.methods:
        cases[f"gttnet reconstruct RECORDING --method {m}"] = [
            py, "-m", "gttnet", "reconstruct", str(project), "--method", m, "--json", "--quiet",
        ]  # fmt: skip
    rows = []
    for name, cmd in cases.items():
        run_child(cmd)  # warm the file cache
        walls, cpus, rss, last = [], [], [], ""
        for _ in range(args.runs):
            wall, cpu, mb, last = run_child(cmd)
            walls.append(wall)
            cpus.append(cpu)
            rss.append(mb)
        summary = json.loads(last) if last.startswith("{") else {}
        rows.append((name, walls, cpus, rss, summary))
        print(f"{name}: {statistics.median(walls):.2f} s", file=sys.stderr, flush=True)
    threads = os.environ.get("OMP_NUM_THREADS", "1")
    print(f"\n{args.images}-image recording (`gttdata export` of recipes/gttdata/long.yaml), {args.runs} runs each, "
          f"OMP_NUM_THREADS={threads}; median (min..max)")  # fmt: skip
    print("| command | wall s | CPU s | peak RSS MB | method ran | MPJPE mm |")
    print("|---|---|---|---|---|---|")
    for name, walls, cpus, rss, s in rows:
        ran = s.get("method", "-")
        err = f"{s['mpjpe_mm']:.1f}" if "mpjpe_mm" in s else "-"
        print(f"| `{name}` | {fmt(walls, '.2f')} | {fmt(cpus, '.2f')} | {fmt(rss, '.0f')} | {ran} | {err} |")
    if not args.split:
        return
    cpu = {name: statistics.median(c) for name, _, c, _, _ in rows}
    cli = cpu["gttnet reconstruct --help"]
    sci = cpu["python -c 'import numpy, scipy.sparse, scipy.linalg, scipy.optimize' (baseline)"]
    print(
        f"\nCPU seconds of each run split (medians over {args.runs} fresh processes that run the command twice): "
        "first run = imports and first uses + work, second run = the work alone"
    )
    print("| method | whole process | interpreter + CLI | first run | second run (work) | imports and first uses | "
          "import numpy + SciPy |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for m in args.methods:
        cmd = ["reconstruct", str(project), "--method", m, "--json", "--quiet"]
        splits = [run_split(cmd) for _ in range(args.runs)]
        first = [d["first"] for d in splits]
        second = [d["second"] for d in splits]
        imports = [a - b for a, b in zip(first, second, strict=True)]
        total = cpu[f"gttnet reconstruct RECORDING --method {m}"]
        print(f"| {m} | {total:.2f} | {cli:.2f} | {fmt(first, '.2f')} | {fmt(second, '.2f')} | "
              f"{fmt(imports, '.2f')} | {sci:.2f} |")  # fmt: skip


if __name__ == "__main__":
    main()
