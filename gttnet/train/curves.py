"""Learning curves of a training run: loss per stage and validation MPJPE per sequencing condition."""

from __future__ import annotations

import json
import logging
from pathlib import Path

__all__ = ["plot_learning_curves", "read_history"]

log = logging.getLogger(__name__)

CONDITIONS = ("none", "partial", "full")


def read_history(run_dir: str | Path) -> list[dict]:
    """The train and validation records of a run's ``log.jsonl`` (meta records dropped)."""
    path = Path(run_dir) / "log.jsonl"
    records = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [r for r in records if r.get("kind") in ("train", "val")]


def _stages(history: list[dict]) -> list[tuple[int, str, int]]:
    """``(stage_index, name, first global step)`` of every stage seen, in order."""
    seen: dict[int, tuple[int, str, int]] = {}
    for r in history:
        si = r.get("stage_index", 0)
        first = r["global_step"] - r["step"]
        if si not in seen or first < seen[si][2]:
            seen[si] = (si, r.get("stage", str(si)), first)
    return [seen[k] for k in sorted(seen)]


def plot_learning_curves(history: list[dict], path: str | Path, *, title: str | None = None) -> Path | None:
    """Plot a run's learning curves to ``path`` (PNG); None when matplotlib is not installed.

    Left: the training loss of each stage (mean over each logging window; its own line, log scale: the
    stages weight different losses, so their totals are not comparable) and the validation loss, points joined within a stage only.
    Right: validation MPJPE (mm, median over the validation captures: a few captures with most joints out
    of view dominate means) per sequencing condition, and of X_init (the pseudo-triangulation the network
    starts from). Stage changes are dashed vertical lines labelled with the stage name; tick
    labels are plain numbers.

    Args:
        history: Train and validation records (``LoopState.history`` or :func:`read_history`).
        path: Output PNG.
        title: Figure title.

    Returns:
        The path written, or None.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        from matplotlib.ticker import FuncFormatter
    except ImportError:
        log.info("matplotlib not installed: no learning curves")
        return None
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    fig, (ax_loss, ax_mm) = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    stages = _stages(history)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for si, name, _ in stages:
        c = colours[si % len(colours)]
        tr = [r for r in history if r["kind"] == "train" and r.get("stage_index", 0) == si]
        va = [r for r in history if r["kind"] == "val" and r.get("stage_index", 0) == si]
        if tr:
            ax_loss.plot([r["global_step"] for r in tr], [r["loss"] for r in tr], color=c, lw=1,
                         label=f"train: {name}")  # fmt: skip
        if va:
            ax_loss.plot([r["global_step"] for r in va], [r["loss"] for r in va], "o-", color=c, mfc="white",
                         ms=4, label=f"validation: {name}")  # fmt: skip
            steps = [r["global_step"] for r in va]
            for k, cond in enumerate(CONDITIONS):
                key = f"mpjpe_{cond}_median_mm"
                if any(key in r for r in va):
                    ax_mm.plot(steps, [r.get(key, float("nan")) for r in va], "o-", ms=3,
                               color=colours[k % len(colours)], label=cond if si == stages[-1][0] else None)  # fmt: skip
            if not any(f"mpjpe_{c}_median_mm" in r for r in va for c in CONDITIONS):
                ax_mm.plot(steps, [r["mpjpe_median_mm"] for r in va], "o-", ms=3, color="black",
                           label="all conditions" if si == stages[-1][0] else None)  # fmt: skip
            ax_mm.plot(steps, [r["mpjpe_init_median_mm"] for r in va], "x:", ms=3, color="grey",
                       label="X_init" if si == stages[-1][0] else None)  # fmt: skip
    for ax in (ax_loss, ax_mm):
        for _, name, first in stages:
            if first > 0:
                ax.axvline(first, color="black", ls="--", lw=0.8)
                ax.annotate(name, (first, 1.0), xycoords=("data", "axes fraction"), xytext=(3, -12),
                            textcoords="offset points", fontsize=8)  # fmt: skip
            else:
                ax.annotate(name, (0.0, 1.0), xycoords="axes fraction", xytext=(3, -12),
                            textcoords="offset points", fontsize=8)  # fmt: skip
        ax.set_xlabel("step")
        ax.xaxis.set_major_formatter(plain)
    ax_loss.set_yscale("log")
    ax_loss.set_ylabel("loss (each stage's weighted sum)")
    ax_mm.set_ylabel("validation MPJPE, median over captures (mm)")
    ax_mm.yaxis.set_major_formatter(plain)
    ax_loss.yaxis.set_major_formatter(plain)
    # Minor ticks of the log axis as plain numbers: all of them inside one decade, else 2x and 5x only.
    lo, hi = ax_loss.get_ylim()
    digits = "123456789" if hi < 10 * lo else "25"
    ax_loss.yaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:.3g}" if f"{v:e}"[0] in digits else ""))
    ax_loss.legend(fontsize=7)
    ax_mm.legend(fontsize=7, title="sequencing", title_fontsize=7)
    if title:
        fig.suptitle(title)
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
