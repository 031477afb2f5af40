"""Several people in an unsynchronized Pose2Sim trial: the subject alone, with a bystander, and two people.

Two people are reconstructed with --subjects 2 (identity checked against both truths).

    python benchmarks/bench_people.py [--bystander 0.1] [--seeds 3]

Prints a table of median marker errors in mm (the TRC against the simulated walk at its times). The trial
is tests/integration/_pose2sim_trial.py's (4 cameras at 30 Hz started 0, 5, 12 and 3 frames late, BODY_25B,
1 px noise); the second person walks 1.5 m beside the subject in every frame of every camera; the
bystander is detected by camera 2 only, confidently, in the given fraction of its frames.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from gttnet.cli import main
from tests.integration._pose2sim_trial import write_session
from tests.integration.test_recording_people import DROP, SIDE, _add_people, _error_mm


def _run(*args) -> dict:
    res = CliRunner().invoke(main, ["reconstruct", *map(str, args), "--json", "--quiet"])
    if res.exit_code != 0:
        raise SystemExit(res.output)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main_(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bystander", type=float, default=0.1)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--method", default="sync")
    a = ap.parse_args(argv)
    rows = []
    for seed in range(a.seeds):
        with tempfile.TemporaryDirectory() as d:
            root = Path(d)
            alone, _, _ = write_session(root / "a", drop=DROP, seed=seed)
            by, rig, _ = write_session(root / "b", drop=DROP, seed=seed)
            _add_people(by, rig, second=False, bystander_frac=a.bystander, seed=seed)
            two, rig2, _ = write_session(root / "c", drop=DROP, seed=seed)
            _add_people(two, rig2, second=True, bystander_frac=a.bystander, seed=seed)
            _run(alone, "--out", root / "alone.trc", "--method", a.method)
            _run(by, "--out", root / "by.trc", "--method", a.method)
            _run(two, "--out", root / "two.trc", "--method", a.method, "--subjects", "2")
            e = [_error_mm(root / f"two_p{k}.trc", off) for k in (0, 1) for off in (None, SIDE)]
            best = [min(e[0], e[1]), min(e[2], e[3])]
            switched = not ((e[0] < e[1]) != (e[2] < e[3]))  # both outputs nearest the same person
            rows.append((seed, _error_mm(root / "alone.trc"), _error_mm(root / "by.trc"), *best, switched))
    print(
        "| seed | alone mm | with bystander mm | ratio | --subjects 2: p0 mm | p1 mm | worst ratio | identity mixed |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for s, al, by, p0, p1, sw in rows:
        print(
            f"| {s} | {al:.2f} | {by:.2f} | {by / al:.2f} | {p0:.2f} | {p1:.2f} | {max(p0, p1) / al:.2f} | {sw} |"
        )
    r = np.array([[by / al, max(p0, p1) / al] for _, al, by, p0, p1, _ in rows])
    print(
        f"\nmedian ratio with bystander {np.median(r[:, 0]):.2f}, two people (worst of the two) {np.median(r[:, 1]):.2f}"
    )


if __name__ == "__main__":
    main_()
