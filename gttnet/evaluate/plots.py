"""PNG figures of evaluation results: error sweeps (paper Fig. 3), runtime, affinity and segmentation views."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gttnet.evaluate.summary import mean_interval

__all__ = ["plot_sweeps", "plot_runtime", "plot_affinity"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_sweeps(rows: list[dict], recipe, out_dir: str | Path) -> list[Path]:
    """One figure per swept condition: MPJPE vs value, a line per method, a panel per sequencing condition.

    Points are the mean over sequences with ``recipe.error_bars`` (``ci95``: 95% percentile-bootstrap
    interval of the mean; ``std``: sample standard deviation clipped at zero, see
    :func:`~gttnet.evaluate.summary.mean_interval`, so no bar reaches below zero error), or with ``recipe.plot_statistic == "median"`` the median with
    the interquartile range; the figure title says which.

    Args:
        rows: Rows of ``errors.csv``.
        recipe: The :class:`~gttnet.evaluate.recipe.EvalRecipe` (labels, sequencing order).
        out_dir: Directory of the ``sweep_<condition>.png`` files.

    Returns:
        The written paths.
    """
    plt = _pyplot()
    out = Path(out_dir)
    labels = {s.name: s.label or s.variable for s in recipe.sweeps}
    methods = [m.name for m in recipe.methods]
    median = recipe.plot_statistic == "median"
    bars = "95% bootstrap CI of the mean" if recipe.error_bars == "ci95" else "±1 std, clipped at 0"
    bars = "median, bars: interquartile range" if median else f"mean, bars: {bars}"
    paths = []
    for cond in dict.fromkeys(r["condition"] for r in rows):
        crow = [r for r in rows if r["condition"] == cond and r["status"] == "ok" and r["mpjpe_mm"]]
        seqs = list(recipe.sequencing)
        fig, axes = plt.subplots(1, len(seqs), figsize=(4.2 * len(seqs), 3.6), sharey=True, squeeze=False)
        for ax, seq in zip(axes[0], seqs, strict=True):
            for k, m in enumerate(methods):
                pts = [r for r in crow if r["sequencing"] == seq and r["method"] == m]
                if not pts:
                    continue
                xs = sorted({float(r["value"]) for r in pts})
                vals = [np.array([float(r["mpjpe_mm"]) for r in pts if float(r["value"]) == x]) for x in xs]
                if median:
                    q = np.array([np.percentile(v, [25, 50, 75]) for v in vals])
                    ys, es = q[:, 1], np.stack([q[:, 1] - q[:, 0], q[:, 2] - q[:, 1]])
                else:
                    ys = np.array([v.mean() for v in vals])
                    iv = np.array([mean_interval(v, recipe.error_bars) for v in vals]).reshape(-1, 2)
                    es = np.stack([ys - iv[:, 0], iv[:, 1] - ys])
                ax.errorbar(xs, ys, yerr=es, marker="o", ms=4, capsize=3, label=m, color=f"C{k}")
            ax.set_title(f"sequencing: {seq}")
            ax.set_xlabel(labels.get(cond, cond))
            ax.grid(alpha=0.3)
        axes[0, 0].set_ylabel("MPJPE [mm]")
        handles, names = [], []
        for ax in axes[0]:
            for h, n in zip(*ax.get_legend_handles_labels(), strict=True):
                if n not in names:
                    handles.append(h)
                    names.append(n)
        if handles:
            fig.legend(handles, names, loc="upper right", fontsize=8)
        fig.suptitle(f"{recipe.name}: {cond} ({bars})", fontsize=10)
        fig.tight_layout(rect=(0, 0, 0.9, 0.95))
        p = out / f"sweep_{cond}.png"
        fig.savefig(p, dpi=110)
        plt.close(fig)
        paths.append(p)
    return paths


def plot_runtime(lengths: list[int], seconds: dict[str, list[float]], path: str | Path) -> Path:
    """Time per sequence vs number of images, log-scale y, a line per method (paper Fig. 5a).

    Args:
        lengths: Sequence lengths (images).
        seconds: Method name -> seconds per length (NaN where not run).
        path: Output PNG.
    """
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(4.8, 3.6))
    for k, (m, s) in enumerate(seconds.items()):
        ax.plot(lengths, s, marker="o", label=m, color=f"C{k}")
    ax.set_yscale("log")
    ax.set_xlabel("images per sequence")
    ax.set_ylabel("seconds per sequence (log)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)


def plot_affinity(
    affinity: np.ndarray,
    labels: np.ndarray,
    order: np.ndarray,
    path: str | Path,
    *,
    title: str = "",
    embedding: np.ndarray | None = None,
) -> Path:
    """Affinity matrix with images sorted by label then order, beside the 2-D spectral embedding.

    Args:
        affinity: Affinity, shape ``(N, N)``.
        labels: Cluster/event label per image, shape ``(N,)``.
        order: Rank of each image inside its cluster, shape ``(N,)``.
        path: Output PNG.
        title: Figure title.
        embedding: Spectral coordinates, shape ``(N, >=2)``; computed from ``affinity`` when None.
    """
    plt = _pyplot()
    A = np.asarray(affinity, dtype=np.float64)
    S = 0.5 * (A + A.T)
    idx = np.lexsort((order, labels))
    if embedding is None:
        from gttnet.geometry.ordering import spectral_embedding

        embedding = spectral_embedding(S, 3)[:, 1:]
    fig, (a0, a1) = plt.subplots(1, 2, figsize=(9.0, 4.2))
    a0.imshow(S[np.ix_(idx, idx)] > 0, cmap="Greys", interpolation="nearest")
    a0.set_title("affinity (sorted by label, then order)", fontsize=9)
    a0.set_xlabel("image")
    a0.set_ylabel("image")
    for k, lab in enumerate(np.unique(labels)):
        sel = labels == lab
        a1.scatter(embedding[sel, 0], embedding[sel, -1], s=8, color=f"C{k % 10}", label=f"{lab}")
    a1.set_title("spectral embedding", fontsize=9)
    a1.legend(fontsize=7, title="label", title_fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
