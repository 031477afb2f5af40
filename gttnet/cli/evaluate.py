"""The ``gttnet evaluate`` command: run an evaluation recipe (sweeps x sequencing x methods) into a run dir."""

from __future__ import annotations

import logging

import click

from gttdata.errors import friendly_errors

__all__ = ["register", "evaluate_cmd"]

log = logging.getLogger(__name__)


@click.command("evaluate")
@click.argument("recipe_path", metavar="RECIPE", type=click.Path(dir_okay=False))
@click.argument("overrides", nargs=-1)
@click.option(
    "--workers", type=click.IntRange(min=1), default=None, help="Worker processes [default: recipe's]."
)
@click.option("--out", "output_dir", type=click.Path(file_okay=False), default=None, help="Run directory.")
@click.option("--no-resume", is_flag=True, help="Refuse to continue an existing errors.csv.")
@click.option("--no-plots", is_flag=True, help="Skip the PNG plots.")
@click.option("--runtime", "runtime_only", is_flag=True, help="Run only the recipe's runtime study.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@friendly_errors
def evaluate_cmd(recipe_path, overrides, workers, output_dir, no_resume, no_plots, runtime_only, quiet):
    """Evaluate methods on RECIPE's test sequences; OVERRIDES are key.sub=value.

    Writes errors.csv (one row per sample, sequencing and method; skipped methods carry a note),
    summary.md and sweep_<condition>.png into the recipe's output_dir. A rerun resumes: finished jobs
    are kept, the others run.

    \b
    Example:
      gttnet evaluate recipes/gttnet/eval_smoke.yaml data.n_sequences=1 --workers 2
    """
    from gttnet.evaluate.recipe import RuntimeSpec, load_eval_recipe
    from gttnet.evaluate.run import evaluate
    from gttnet.evaluate.runtime import run_runtime

    ovr = list(overrides) + ([f"output_dir={output_dir}"] if output_dir else [])
    recipe = load_eval_recipe(recipe_path, ovr)
    if runtime_only:
        out = f"{recipe.output_dir}/runtime"
        res = run_runtime(recipe.runtime or RuntimeSpec(), out, progress=not quiet)
        click.echo(res.markdown)
        click.echo(f"runtime study -> {out}")
        return
    run_dir = evaluate(recipe, workers=workers, resume=not no_resume, progress=not quiet, plots=not no_plots)
    click.echo((run_dir / "summary.md").read_text())
    click.echo(f"evaluation -> {run_dir}")


def register(main: click.Group) -> None:
    """Attach ``evaluate`` to the ``gttnet`` command group."""
    main.add_command(evaluate_cmd)
