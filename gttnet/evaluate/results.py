"""The results table of an evaluation run: ``errors.csv`` rows, appended durably, read back for resume."""

from __future__ import annotations

import csv
import logging
import os
from collections.abc import Iterable
from pathlib import Path

__all__ = ["CSV_FIELDS", "make_row", "read_rows", "done_pairs", "clean_csv", "append_rows"]

log = logging.getLogger(__name__)

#: Columns of ``errors.csv`` (``value`` is in plotted units: the recipe value times the sweep's scale).
CSV_FIELDS: tuple[str, ...] = (
    "job_id",
    "condition",
    "variable",
    "value",
    "sequencing",
    "method",
    "sample",
    "n_images",
    "mpjpe_mm",
    "kendall_tau",
    "seconds",
    "status",
    "note",
    "offset_err_frames",
)


def make_row(job, seq: str, name: str, n: int, **fields) -> dict:
    """One ``errors.csv`` row of ``job`` (a :class:`~gttnet.evaluate.jobs.Job`): defaults, then ``fields``."""
    row = {
        "job_id": job.job_id,
        "condition": job.condition,
        "variable": job.variable,
        "value": f"{job.value:g}",
        "sequencing": seq,
        "method": name,
        "sample": job.sample,
        "n_images": n,
        "mpjpe_mm": "",
        "kendall_tau": "",
        "seconds": "",
        "status": "ok",
        "note": "",
        "offset_err_frames": "",
    }
    row.update(fields)
    row["note"] = " ".join(str(row["note"]).split())  # one line per row: resume counts lines
    return row


def read_rows(path: str | Path) -> list[dict]:
    """Rows of an ``errors.csv`` (rows cut short by a kill are dropped)."""
    p = Path(path)
    if not p.is_file():
        return []
    with p.open(newline="") as f:
        return [r for r in csv.DictReader(f) if None not in r and None not in r.values()]


def done_pairs(rows: list[dict]) -> dict[str, set[tuple[str, str]]]:
    """``job_id`` -> the ``(sequencing, method)`` cells already in ``rows``."""
    done: dict[str, set[tuple[str, str]]] = {}
    for r in rows:
        done.setdefault(r["job_id"], set()).add((r["sequencing"], r["method"]))
    return done


def clean_csv(path: Path) -> list[dict]:
    """Valid rows of an existing CSV; rewrites it when a kill left a torn or malformed last row."""
    if not path.is_file():
        return []
    rows = read_rows(path)
    text = path.read_text()
    if text and (not text.endswith("\n") or text.count("\n") != len(rows) + 1):
        log.info("%s: dropping a torn row left by an interrupted run", path)
        path.unlink()
        append_rows(path, rows)
    return rows


def append_rows(path: Path, rows: Iterable[dict]) -> None:
    """Append rows (header first for a new file) and fsync, so a kill loses at most the row being written."""
    new = not path.is_file()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=CSV_FIELDS)
        if new:
            w.writeheader()
        w.writerows(rows)
        f.flush()
        os.fsync(f.fileno())
