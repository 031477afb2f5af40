"""Aggregate statistics of evaluation rows and their Markdown summary."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

__all__ = ["GroupStats", "group_stats", "error_bar", "mean_interval", "summary_markdown", "write_summary"]


@dataclass(frozen=True)
class GroupStats:
    """MPJPE and order statistics of one (condition, value, sequencing, method) cell.

    Args:
        condition: Sweep name.
        value: Swept value (plotted units).
        sequencing: Sequencing condition.
        method: Method column name.
        n: Sequences with a result.
        mean_mm: Mean MPJPE over sequences, mm (NaN when n = 0).
        median_mm: Median MPJPE, mm.
        std_mm: Sample standard deviation, mm.
        ci95_mm: Half-width of the 95% t-interval of the mean, mm.
        tau: Mean Kendall tau of the recovered order (NaN when none).
        seconds: Mean time per sequence, s.
        note: Reason when every sequence was skipped or failed.
    """

    condition: str
    value: float
    sequencing: str
    method: str
    n: int
    mean_mm: float
    median_mm: float
    std_mm: float
    ci95_mm: float
    tau: float
    seconds: float
    note: str = ""


def _floats(rows: list[dict], key: str) -> np.ndarray:
    return np.array([float(r[key]) for r in rows if r.get(key, "") not in ("", None)], dtype=np.float64)


def error_bar(values: np.ndarray, kind: str) -> float:
    """Half-width of an error bar: ``std`` (sample std) or ``ci95`` (95% Student-t interval of the mean)."""
    n = values.shape[0]
    if n < 2:
        return 0.0
    sd = float(values.std(ddof=1))
    return sd if kind == "std" else float(stats.t.ppf(0.975, n - 1) * sd / np.sqrt(n))


def mean_interval(values: np.ndarray, kind: str, *, n_boot: int = 4000, seed: int = 0) -> tuple[float, float]:
    """Interval drawn around the mean in the sweep plots, ``(low, high)``.

    ``ci95``: the 95 % percentile-bootstrap interval of the mean (``n_boot`` resamples, fixed ``seed``), which
    stays inside the range of the values, so an error is never drawn below zero; ``std``: mean +- one sample
    standard deviation, clipped at zero. A single value gives ``(value, value)``.

    Args:
        values: Per-sequence errors (non-negative), shape ``(n,)``.
        kind: ``ci95`` or ``std``.
        n_boot: Bootstrap resamples for ``ci95``.
        seed: Seed of the bootstrap resampling (the interval is reproducible).

    Returns:
        ``(low, high)``.
    """
    v = np.asarray(values, dtype=np.float64)
    m = float(v.mean())
    if v.shape[0] < 2:
        return m, m
    if kind == "std":
        sd = float(v.std(ddof=1))
        return max(m - sd, 0.0), m + sd
    idx = np.random.default_rng(seed).integers(0, v.shape[0], size=(n_boot, v.shape[0]))
    lo, hi = np.percentile(v[idx].mean(axis=1), [2.5, 97.5])
    return float(lo), float(hi)


def group_stats(rows: list[dict]) -> list[GroupStats]:
    """Statistics per (condition, value, sequencing, method), in first-seen order of the rows."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["condition"], float(r["value"]), r["sequencing"], r["method"]), []).append(r)
    out = []
    for (cond, value, seq, method), rs in groups.items():
        ok = [r for r in rs if r["status"] == "ok"]
        e = _floats(ok, "mpjpe_mm")
        tau = _floats(ok, "kendall_tau")
        sec = _floats(ok, "seconds")
        nan = float("nan")
        notes = sorted({r["note"] for r in rs if r["status"] != "ok" and r["note"]})
        out.append(
            GroupStats(
                cond,
                value,
                seq,
                method,
                int(e.shape[0]),
                float(e.mean()) if e.size else nan,
                float(np.median(e)) if e.size else nan,
                float(e.std(ddof=1)) if e.size > 1 else 0.0,
                error_bar(e, "ci95"),
                float(tau.mean()) if tau.size else nan,
                float(sec.mean()) if sec.size else nan,
                "; ".join(notes),
            )
        )
    return out


def _fmt(x: float, digits: int = 1) -> str:
    return "–" if not np.isfinite(x) else f"{x:.{digits}f}"


def summary_markdown(
    rows: list[dict], *, title: str = "Evaluation", error_bars: str = "ci95", statistic: str = "mean"
) -> str:
    """Markdown tables: per condition, mean / median MPJPE (mm) and mean Kendall tau per method and value.

    Args:
        rows: Rows of ``errors.csv``.
        title: Heading.
        error_bars: What the plots' error bars show (stated in the text).
        statistic: What the plots show, ``mean`` or ``median``.

    Returns:
        The Markdown text.
    """
    st = group_stats(rows)
    bars = (
        "95% bootstrap interval of the mean"
        if error_bars == "ci95"
        else "± one sample standard deviation, clipped at zero"
    )
    if statistic == "median":
        bars = "median with the interquartile range"
    lines = [
        f"# {title}",
        "",
        "Cells: mean / median MPJPE over sequences in mm (all images and joints, missing ones included), "
        "then (mean Kendall tau of the recovered image order, up to reversal); `skip` = the method lacks "
        f"its sequencing or model (see Notes). Plots: {bars}.",
        "",
    ]
    for cond in dict.fromkeys(s.condition for s in st):
        cs = [s for s in st if s.condition == cond]
        values = sorted({s.value for s in cs})
        lines += [
            f"## {cond}",
            "",
            "| sequencing | method | "
            + " | ".join("all" if cond == "base" else f"{v:g}" for v in values)
            + " |",
        ]
        lines.append("|---|---|" + "---|" * len(values))
        for seq in dict.fromkeys(s.sequencing for s in cs):
            for method in dict.fromkeys(s.method for s in cs if s.sequencing == seq):
                cells = []
                for v in values:
                    g = next(
                        (s for s in cs if s.sequencing == seq and s.method == method and s.value == v), None
                    )
                    if g is None or g.n == 0:
                        cells.append("skip" if g is not None and "skip" in _status(rows, g) else "–")
                    else:
                        cells.append(f"{_fmt(g.mean_mm)} / {_fmt(g.median_mm)} ({_fmt(g.tau, 2)})")
                lines.append(f"| {seq} | {method} | " + " | ".join(cells) + " |")
        n = max((s.n for s in cs), default=0)
        lines += ["", f"Sequences per cell: up to {n}.", ""]
    notes = sorted({(s.method, s.sequencing, s.note) for s in st if s.note})
    if notes:
        lines += ["## Notes", ""]
        lines += [f"- {m} ({seq}): {note}" for m, seq, note in notes]
        lines.append("")
    return "\n".join(lines)


def _status(rows: list[dict], g: GroupStats) -> str:
    for r in rows:
        if r["method"] == g.method and r["sequencing"] == g.sequencing and r["condition"] == g.condition:
            if r["status"] == "skipped":
                return "skip"
    return ""


def write_summary(rows: list[dict], recipe, path: str | Path) -> Path:
    """Write :func:`summary_markdown` of ``rows`` for a recipe to ``path``."""
    p = Path(path)
    text = summary_markdown(
        rows,
        title=f"Evaluation: {recipe.name}",
        error_bars=recipe.error_bars,
        statistic=recipe.plot_statistic,
    )
    p.write_text(text)
    return p
