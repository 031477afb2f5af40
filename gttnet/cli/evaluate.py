"""The ``gttnet evaluate`` command: run an evaluation recipe (sweeps x sequencing x methods) into a run dir."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import click

from gttdata.errors import friendly_errors
from gttdata.threads import threads_option

__all__ = ["register", "evaluate_cmd"]

log = logging.getLogger(__name__)


#: Files an evaluation writes into its run folder (what --overwrite removes).
_RUN_FILES = ("errors.csv", "summary.md", "recipe.json")


def _prepare_run_dir(output_dir: str, resume: bool, overwrite: bool) -> None:
    """Apply docs/CLI.md's rule to an existing run folder: refuse, keep (--resume) or clear (--overwrite)."""
    import shutil
    from pathlib import Path

    out = Path(output_dir)
    if not (out / "errors.csv").exists():
        return
    if resume:
        return
    if not overwrite:
        raise click.ClickException(
            f"{out}: holds an evaluation (errors.csv); pass --resume to continue it or --overwrite to replace it"
        )
    for name in _RUN_FILES:
        (out / name).unlink(missing_ok=True)
    for png in out.glob("sweep_*.png"):
        png.unlink()
    shutil.rmtree(out / "runtime", ignore_errors=True)


@click.command("evaluate")
@click.argument("recipe_path", metavar="RECIPE", type=click.Path(dir_okay=False))
@click.argument("overrides", nargs=-1, metavar="[KEY=VALUE]...")
@click.option(
    "--workers",
    "-j",
    type=click.IntRange(min=1),
    default=None,
    help="Worker processes [default: the recipe's].",
)
@click.option(
    "--out",
    "output_dir",
    type=click.Path(file_okay=False),
    default=None,
    help="Run folder (overrides output_dir).",
)
@click.option(
    "--resume",
    is_flag=True,
    help="Continue the evaluation in the run folder: keep its finished rows, run the rest (also runs "
    "methods added to the recipe since).",
)
@click.option("--overwrite", is_flag=True, help="Replace the evaluation already in the run folder.")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@click.option("--runtime", "runtime_only", is_flag=True, help="Run only the recipe's runtime study.")
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the summary (implies --no-progress).")
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object (run folder and, per cell, MPJPE mean/median and Kendall tau) instead of the summary.",
)
@threads_option
@friendly_errors
def evaluate_cmd(
    recipe_path,
    overrides,
    workers,
    output_dir,
    resume,
    overwrite,
    no_plots,
    runtime_only,
    progress,
    quiet,
    as_json,
):
    """Evaluate methods on RECIPE's test sequences; OVERRIDES are key.sub=value.

    Writes errors.csv (one row per sample, sequencing and method; skipped methods carry a note),
    summary.md and sweep_<condition>.png into the recipe's output_dir (or --out). An existing evaluation
    there is continued with --resume, replaced with --overwrite, and otherwise refused.

    \b
    Examples:
      gttnet evaluate recipes/gttnet/eval_smoke.yaml --out runs/eval_smoke
      gttnet evaluate recipes/gttnet/eval_smoke.yaml data.n_sequences=1 --workers 2 --out runs/eval_one --resume
      gttnet evaluate recipes/gttnet/eval_smoke.yaml --out runs/eval_smoke --resume --json
    """
    from gttnet.evaluate.recipe import RuntimeSpec, load_eval_recipe
    from gttnet.evaluate.run import evaluate
    from gttnet.evaluate.runtime import run_runtime

    if resume and overwrite:
        raise click.UsageError("--resume and --overwrite exclude each other")
    progress = progress and not quiet
    ovr = list(overrides) + ([f"output_dir={output_dir}"] if output_dir else [])
    recipe = load_eval_recipe(recipe_path, ovr)
    if runtime_only:
        out = f"{recipe.output_dir}/runtime"
        res = run_runtime(recipe.runtime or RuntimeSpec(), out, progress=progress and not as_json)
        if as_json:
            report = {
                "runtime_dir": out,
                "lengths": res.lengths,
                "n_images": res.n_images,
                "seconds": res.seconds,
            }
            click.echo(json.dumps(report))
            return
        click.echo(res.markdown)
        click.echo(f"runtime study -> {out}")
        return
    _prepare_run_dir(recipe.output_dir, resume, overwrite)
    run_dir = evaluate(
        recipe, workers=workers, resume=True, progress=progress and not as_json, plots=not no_plots
    )
    if as_json:
        click.echo(json.dumps({"run_dir": str(run_dir), **cell_summary(run_dir / "errors.csv")}))
        return
    click.echo((run_dir / "summary.md").read_text())
    click.echo(f"evaluation -> {run_dir}")


def cell_summary(errors_csv: Path) -> dict:
    """Per cell of ``errors.csv`` (condition, value, sequencing, method): counts and error statistics.

    The statistics are :func:`gttnet.evaluate.summary.group_stats`, the ones ``summary.md`` shows.

    Args:
        errors_csv: An evaluation's ``errors.csv``.

    Returns:
        ``{"errors_csv": path, "cells": [...]}``; each cell has ``condition``, ``variable``, ``value``,
        ``sequencing``, ``method``, ``n_ok``, ``n_skipped``, ``mpjpe_mm_mean``, ``mpjpe_mm_median`` and
        ``kendall_tau_mean`` (None where no row finished).
    """
    import math
    from collections import Counter

    from gttnet.evaluate.results import read_rows
    from gttnet.evaluate.summary import group_stats

    rows = read_rows(errors_csv)
    variable = {r["condition"]: r["variable"] for r in rows}
    n_rows = Counter((r["condition"], float(r["value"]), r["sequencing"], r["method"]) for r in rows)

    def number(x: float) -> float | None:
        return None if math.isnan(x) else x

    cells = [
        {
            "condition": g.condition,
            "variable": variable[g.condition],
            "value": f"{g.value:g}",
            "sequencing": g.sequencing,
            "method": g.method,
            "n_ok": g.n,
            "n_skipped": n_rows[(g.condition, g.value, g.sequencing, g.method)] - g.n,
            "mpjpe_mm_mean": number(g.mean_mm),
            "mpjpe_mm_median": number(g.median_mm),
            "kendall_tau_mean": number(g.tau),
        }
        for g in group_stats(rows)
    ]
    return {"errors_csv": str(errors_csv), "cells": cells}


def register(main: click.Group) -> None:
    """Attach ``evaluate`` to the ``gttnet`` command group."""
    main.add_command(evaluate_cmd)
