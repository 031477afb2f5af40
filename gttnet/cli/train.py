"""``gttnet train``: run or resume a GTT-Net training recipe."""

from __future__ import annotations

import json
import logging
import os
import warnings
from pathlib import Path

import click

from gttdata._cli_common import not_a_warning_line
from gttdata.errors import friendly_errors
from gttdata.threads import threads_option

__all__ = ["register", "train_command"]


@click.command("train")
@click.argument("recipe", required=False, type=click.Path(dir_okay=True))
@click.argument("overrides", nargs=-1, metavar="[KEY=VALUE]...")
@click.option(
    "--out",
    "out",
    type=click.Path(file_okay=False),
    help="Run folder (default: the recipe's output_dir, else runs/<name>); refused if it holds a run, "
    "unless --resume/--overwrite.",
)
@click.option(
    "--resume",
    is_flag=True,
    help="Continue the interrupted run in --out from its checkpoint (same recipe only). Without RECIPE, "
    "the recipe the run saved is used.",
)
@click.option("--overwrite", is_flag=True, help="Replace the run already in --out (its files are deleted).")
@click.option(
    "--device", type=click.Choice(["auto", "cpu", "cuda"]), default=None, help="Override train.device."
)
@click.option("--max-steps", type=int, default=None, help="Stop (with a checkpoint) after this many steps.")
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the result lines (implies --no-progress).")
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object (run folder, status, validation) instead."
)
@threads_option
@friendly_errors
def train_command(
    recipe, overrides, resume, out, device, max_steps, progress, quiet, overwrite, as_json
) -> None:
    """Train GTT-Net with RECIPE (recipes/gttnet/*.yaml) and key.sub=value OVERRIDES.

    The run folder is --out, else the recipe's output_dir (runs/<name> when it has none). An existing
    run there is never overwritten silently: --resume continues it (same recipe), --overwrite replaces
    it. To continue a run without its recipe file, give only --out RUN --resume: the recipe the run
    saved is used.

    \b
    Examples:
      gttnet train recipes/gttnet/tiny.yaml --out runs/tiny
      gttnet train recipes/gttnet/tiny.yaml stages.0.steps=5 --device cpu --out runs/tiny_short --overwrite
      gttnet train --out runs/tiny --resume
    """
    from gttnet.train.loop import train
    from gttnet.train.recipe import load_train_recipe

    if not logging.getLogger().handlers:
        logging.basicConfig(
            level=logging.WARNING if quiet or as_json else logging.INFO,
            format="%(levelname)s %(name)s: %(message)s",
        )
        for handler in logging.getLogger().handlers:  # gttdata/gttnet warnings print as warning: lines
            handler.addFilter(not_a_warning_line)
    recipe, out = _old_resume_form(recipe, overrides, resume, out)
    if recipe is None and not resume:
        raise click.UsageError("give a RECIPE (e.g. recipes/gttnet/tiny.yaml), or --out RUN --resume")
    if recipe is None and out is None:
        raise click.UsageError("--resume without a RECIPE needs --out RUN (the run to continue)")
    if recipe is None and overrides:
        raise click.UsageError(
            "overrides need a RECIPE; --out RUN --resume alone uses the run's saved recipe"
        )
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", FutureWarning)
            parsed = None if recipe is None else load_train_recipe(recipe, overrides)
        for w in caught:
            click.echo(f"warning: {w.message}", err=True)
        result = train(
            parsed,
            out=out,
            device=device,
            resume=resume,
            overwrite=overwrite,
            max_steps=max_steps,
            progress=progress and not (quiet or as_json),
        )
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    if int(os.environ.get("RANK", "0")) != 0:
        return  # under torchrun only rank 0 reports
    val = next((r for r in reversed(result.state.history) if r["kind"] == "val"), None)
    if as_json:
        click.echo(
            json.dumps(
                {
                    "run_dir": str(result.run_dir),
                    "finished": result.finished,
                    "global_step": result.state.global_step,
                    "val_loss": None if val is None else val["loss"],
                    "val_mpjpe_mm": None if val is None else val["mpjpe_mm"],
                    "val_mpjpe_init_mm": None if val is None else val["mpjpe_init_mm"],
                    "model": str(result.run_dir / "model.pt") if result.finished else None,
                }
            )
        )
        return
    status = (
        "finished"
        if result.finished
        else f"stopped at step {result.state.global_step} (continue: gttnet train --out {result.run_dir} --resume)"
    )
    click.echo(f"run {result.run_dir}: {status}")
    if val is not None:
        click.echo(
            f"validation: loss {val['loss']:.4g}, MPJPE {val['mpjpe_mm']:.1f} mm (X_init {val['mpjpe_init_mm']:.1f} mm)"
        )
    if result.finished:
        click.echo(f"model: {result.run_dir / 'model.pt'}")


def _old_resume_form(recipe, overrides, resume, out):
    """``(recipe, out)``, reading the old ``--resume RUN_DIR`` (a folder where RECIPE goes) as ``--out RUN_DIR``.

    A recipe is a file, a run is a folder: ``gttnet train --resume RUN_DIR`` is read as
    ``gttnet train --out RUN_DIR --resume`` with a warning; any other folder given where a value does
    not belong is one line showing the new form.
    """
    new_form = "gttnet train [RECIPE] --out RUN_DIR --resume"
    stray = next((o for o in overrides if "=" not in o), None)
    if stray is not None:  # gttnet train RECIPE --resume RUN_DIR: the folder lands among the overrides
        raise click.UsageError(f"{stray}: expected key.sub=value; --resume takes no folder, use: {new_form}")
    if recipe is None or not (Path(recipe).is_dir() or Path(recipe).suffix.lower() not in (".yaml", ".yml")):
        return recipe, out
    if not resume:
        raise click.UsageError(f"{recipe}: expected a recipe file (.yaml); to continue a run: {new_form}")
    if out is not None and Path(out) != Path(recipe):
        raise click.UsageError(f"{recipe} and --out {out}: give one run folder, as in: {new_form}")
    click.echo(
        f"warning: gttnet train --resume {recipe} is deprecated; use: gttnet train --out {recipe} --resume",
        err=True,
    )
    return None, recipe


def register(main: click.Group) -> None:
    """Attach ``train`` to the gttnet command group."""
    main.add_command(train_command)
