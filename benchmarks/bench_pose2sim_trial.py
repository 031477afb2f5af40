"""A simulated Pose2Sim trial, synchronized and started late, through ``gttnet reconstruct TRIAL_DIR``.

The trial (tests/integration/_pose2sim_trial.py): a 3 s procedural walk on BODY_25B's points, 4 cameras on
a 4 m ring at 30 Hz a quarter frame apart, 1 px detection noise, calibration cameras ``cam_01``... beside
``pose/cam01_json``..., Config.toml with ``frame_rate = 30`` and ``pose_model = "BODY_25B"``, every 17th
frame of one camera ``"people": [{}]``. The late copy starts cameras 2, 3 and 4 by ``--drop`` frames.
Printed: the recovered clock offsets in frames (truth: v / 4 frames, plus the drop), the TRC's median
marker error against the walk, the median distance between the two TRCs, and the median pixel error of
``--export-keypoints`` (the detections re-timed onto the common clock) against the projected walk.

    python benchmarks/bench_pose2sim_trial.py --drop 7,3,12
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from click.testing import CliRunner

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gttdata.detectors import read_keypoints  # noqa: E402
from gttnet.cli import main  # noqa: E402
from gttnet.io.motion_files import read_trc  # noqa: E402
from tests.integration._pose2sim_trial import body25b_walk, write_session  # noqa: E402


def run(root: Path, drop: tuple[int, ...]) -> tuple[dict, np.ndarray, np.ndarray, list[float]]:
    """Reconstruct one session; returns the summary, the TRC times and markers, the re-timed pixel errors."""
    trial, rig, _ = write_session(root, drop=drop)
    res = CliRunner().invoke(
        main,
        [
            "reconstruct",
            str(trial),
            "--out",
            str(root / "r.trc"),
            "--export-keypoints",
            str(root / "kp"),
            "--json",
        ],
    )
    if res.exit_code != 0:
        raise SystemExit(res.output)
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    _, t, P, _ = read_trc(root / "r.trc")
    X = body25b_walk()
    px_err = []
    for cam in rig.cameras:
        kp = read_keypoints(root / "kp" / f"{cam.name}_json")
        idx = 4 * kp.frame[4 * kp.frame < X.shape[0]]
        px, _ = cam.project(X[idx])
        px_err.append(float(np.nanmedian(np.linalg.norm(kp.xy[: idx.size] - px, axis=-1))))
    return summary, t, P, px_err


def main_() -> None:
    """Print the offsets and errors of the synchronized trial and its late-started copy."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drop", default="7,3,12", help="frames cameras 2, 3, 4 start late in the copy")
    args = ap.parse_args()
    drop = (0, *(int(x) for x in args.drop.split(",")))
    X = body25b_walk()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, d in (("synced", (0,) * len(drop)), ("late", drop)):
            summary, t, P, px_err = run(Path(tmp) / name, d)
            truth = X[np.rint(t * 120).astype(int)][..., [1, 2, 0]]  # TRC is Y up: X, Y, Z = world y, z, x
            err = 1e3 * float(np.nanmedian(np.linalg.norm(P - truth, axis=-1)))
            offsets = {k: round(v * 30, 3) for k, v in summary["clock_offsets_s"].items()}
            print(f"{name:>6}: method {summary['method']}, offsets (frames) {offsets}")
            print(f"        TRC median marker error vs the walk {err:.2f} mm; re-timed keypoints median px error "
                  + ", ".join(f"{e:.2f}" for e in px_err))  # fmt: skip
            out[name] = P
    n = min(len(out["synced"]), len(out["late"]))
    d = 1e3 * float(np.nanmedian(np.linalg.norm(out["synced"][:n] - out["late"][:n], axis=-1)))
    print(f"synced vs late TRC: median {d:.2f} mm")


if __name__ == "__main__":
    main_()
