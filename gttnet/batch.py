"""Many trials of one session with one command: ``gttnet batch SESSION --out DIR``.

A Pose2Sim session (or participant) folder holds several trial folders that share one calibration. Each
trial is reconstructed by its own ``gttnet reconstruct TRIAL --out DIR/<trial>/result.<suffix> --json``
process, so a trial that fails stops nobody else and reports one line. ``--jobs N`` runs N at once (each
with one BLAS thread); ``--part i/n`` takes every n-th trial starting at the i-th, so that the jobs of a
cluster array (e.g. SLURM's ``--array=1-n``) split a session with no coordination. A trial whose result
exists is skipped unless ``--overwrite``, so an interrupted batch resumes by running it again.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["TrialResult", "list_trials", "parse_part", "run_batch", "summary_table"]


@dataclass
class TrialResult:
    """What one trial's run gave.

    Args:
        trial: Trial folder, relative to the session.
        status: ``"ok"``, ``"skipped"`` (its result existed) or ``"failed"``.
        out: The result file.
        summary: ``gttnet reconstruct --json``'s object (empty when it failed).
        error: The failure's one line.
        seconds: Wall time of the run.
    """

    trial: str
    status: str
    out: str
    summary: dict = field(default_factory=dict)
    error: str = ""
    seconds: float = 0.0


def list_trials(session: str | Path) -> list[Path]:
    """Trial folders of a Pose2Sim session, participant or trial folder, in natural order.

    Raises:
        ValueError: No trial folder (with ``pose/``, ``pose-sync/`` or ``pose-associated/``) below it.
    """
    from gttdata.recording_folders import trial_folders

    session = Path(session)
    trials = trial_folders(session)
    if not trials:
        raise ValueError(
            f"{session}: no trial folder (one holding pose/, pose-sync/ or pose-associated/) at most two levels down"
        )
    return trials


def parse_part(text: str | None) -> tuple[int, int]:
    """``"i/n"`` (1-based) as ``(i, n)``; None is ``(1, 1)``.

    Raises:
        ValueError: Not two integers with 1 <= i <= n.

    Example:
        >>> parse_part("2/4")
        (2, 4)
    """
    if text is None:
        return 1, 1
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise ValueError(
            f"--part: expected i/n with integers 1 <= i <= n (e.g. 2/4), found {text!r}"
        ) from None
    if not 1 <= i <= n:
        raise ValueError(f"--part: expected i/n with 1 <= i <= n, found {text!r}")
    return i, n


def _run_trial(
    session: Path, trial: Path, out_dir: Path, suffix: str, args: Sequence[str], overwrite: bool
) -> TrialResult:
    import time

    rel = trial.relative_to(session) if trial != session else Path(trial.name)
    out = out_dir / rel / f"result{suffix}"
    if out.exists() and not overwrite:
        return TrialResult(str(rel), "skipped", str(out))
    cmd = [sys.executable, "-m", "gttnet", "reconstruct", str(trial), "--out", str(out), "--json", "--quiet"]
    cmd += ["--overwrite", *args] if overwrite else list(args)
    env = dict(
        os.environ, GTT_THREADS="1", OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1"
    )
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
        return TrialResult(
            str(rel),
            "failed",
            str(out),
            error=lines[-1] if lines else f"exit {proc.returncode}",
            seconds=seconds,
        )
    last = [ln for ln in proc.stdout.strip().splitlines() if ln.startswith("{")]
    summary = json.loads(last[-1]) if last else {}
    (out.parent / "summary.json").write_text(json.dumps(summary, indent=1))
    return TrialResult(str(rel), "ok", str(out), summary=summary, seconds=seconds)


def run_batch(
    session: str | Path,
    out_dir: str | Path,
    *,
    args: Sequence[str] = (),
    suffix: str = ".trc",
    jobs: int = 1,
    part: tuple[int, int] = (1, 1),
    overwrite: bool = False,
    on_done: Callable[[TrialResult], None] | None = None,
) -> list[TrialResult]:
    """Reconstruct every trial of ``part`` of a session (see the module docstring).

    Args:
        session: Session, participant or trial folder.
        out_dir: Results go to ``out_dir/<trial>/result<suffix>`` with its ``summary.json``.
        args: More ``gttnet reconstruct`` options, passed to every trial (e.g. ``["--filter", "butterworth:6"]``).
        suffix: Result file suffix (``.trc``, ``.c3d``, ``.csv``, ``.h5``, ``.npz``).
        jobs: Trials run at once.
        part: ``(i, n)``: trials ``i-1, i-1+n, ...`` of the natural order.
        overwrite: Run trials whose result exists again.
        on_done: Called with each result as it finishes (progress).

    Returns:
        One result per trial of the part, in trial order.
    """
    session, out_dir = Path(session), Path(out_dir)
    i, n = part
    trials = list_trials(session)[i - 1 :: n]
    results: list[TrialResult | None] = [None] * len(trials)

    def work(k: int) -> None:
        r = _run_trial(session, trials[k], out_dir, suffix, args, overwrite)
        results[k] = r
        if on_done is not None:
            on_done(r)

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        list(pool.map(work, range(len(trials))))
    return [r for r in results if r is not None]


def _offsets(summary: dict) -> str:
    off = summary.get("clock_offsets_s")
    if isinstance(off, dict):
        return " ".join(f"{k}:{float(v):+.3f}" for k, v in off.items())
    if isinstance(off, list):
        return " ".join(f"{float(v):+.3f}" for v in off)
    return ""


def summary_table(results: Sequence[TrialResult]) -> str:
    """A plain-text table: trial, status, cameras, images, recovered offsets (s), expected error (mm)."""
    rows = [("trial", "status", "cameras", "images", "offsets_s", "expected_error_mm", "seconds")]
    for r in results:
        s = r.summary
        q = s.get("quality") or {}
        cams = s.get("cameras") or s.get("camera_names") or []
        exp = q.get("expected_error_mm")
        rows.append(
            (
                r.trial,
                r.status if r.status != "failed" else f"failed: {r.error}",
                str(len(cams)) if cams else "",
                str(s.get("n_images", "")),
                _offsets(s),
                "" if exp is None else f"{float(exp):.1f}",
                f"{r.seconds:.1f}" if r.seconds else "",
            )
        )
    widths = [max(len(row[c]) for row in rows) for c in range(len(rows[0]))]
    return "\n".join(
        "  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip() for row in rows
    )
