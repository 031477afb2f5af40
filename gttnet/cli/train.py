"""``gttnet train``: run or resume a GTT-Net training recipe."""

from __future__ import annotations

import logging
import os

import click

from gttdata.errors import friendly_errors

__all__ = ["register", "train_command"]


@click.command("train")
@click.argument("recipe", required=False, type=click.Path(dir_okay=False))
@click.argument("overrides", nargs=-1, metavar="[KEY=VALUE]...")
@click.option(
    "--resume",
    "resume",
    is_flag=False,
    flag_value="",
    default=None,
    metavar="[RUN_DIR]",
    help="Continue an interrupted run exactly: the run in --out (same recipe only), or RUN_DIR with its "
    "saved recipe.",
)
@click.option(
    "--out",
    "out",
    type=click.Path(file_okay=False),
    help="Run directory (default: runs/<name>-<time>); refused if it holds a run, unless --resume/--overwrite.",
)
@click.option("--overwrite", is_flag=True, help="Replace the run already in --out (its files are deleted).")
@click.option(
    "--device", type=click.Choice(["auto", "cpu", "cuda"]), default=None, help="Override train.device."
)
@click.option("--max-steps", type=int, default=None, help="Stop (with a checkpoint) after this many steps.")
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the result lines (implies --no-progress).")
@friendly_errors
def train_command(recipe, overrides, resume, out, device, max_steps, progress, quiet, overwrite) -> None:
    """Train GTT-Net with RECIPE (recipes/gttnet/*.yaml) and key.sub=value OVERRIDES.

    An existing run in --out is never overwritten silently: --resume continues it (same recipe),
    --overwrite replaces it.

    \b
    Examples:
      gttnet train recipes/gttnet/tiny.yaml --out runs/tiny
      gttnet train recipes/gttnet/tiny.yaml stages.0.steps=5 --device cpu --out runs/tiny_short --overwrite
      gttnet train recipes/gttnet/tiny.yaml --out runs/tiny --resume
    """
    from gttnet.train.loop import train
    from gttnet.train.recipe import load_train_recipe

    if not logging.getLogger().handlers:
        logging.basicConfig(
            level=logging.WARNING if quiet else logging.INFO, format="%(levelname)s %(name)s: %(message)s"
        )
    if not resume and recipe is None:
        raise click.UsageError("give a RECIPE (e.g. recipes/gttnet/tiny.yaml) or --resume RUN_DIR")
    if resume == "" and out is None:
        raise click.UsageError("--resume without RUN_DIR needs --out RUN_DIR (the run to continue)")
    if resume and recipe is None and overrides:
        raise click.UsageError(
            "overrides cannot be combined with --resume: the run's recipe is used as saved"
        )
    try:
        parsed = None if recipe is None else load_train_recipe(recipe, overrides)
        result = train(
            parsed,
            out=out,
            device=device,
            resume=True if resume == "" else resume,
            overwrite=overwrite,
            max_steps=max_steps,
            progress=progress and not quiet,
        )
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    if int(os.environ.get("RANK", "0")) != 0:
        return  # under torchrun only rank 0 reports
    val = next((r for r in reversed(result.state.history) if r["kind"] == "val"), None)
    status = (
        "finished"
        if result.finished
        else f"stopped at step {result.state.global_step} (resume with --resume)"
    )
    click.echo(f"run {result.run_dir}: {status}")
    if val is not None:
        click.echo(
            f"validation: loss {val['loss']:.4g}, MPJPE {val['mpjpe_mm']:.1f} mm (X_init {val['mpjpe_init_mm']:.1f} mm)"
        )
    if result.finished:
        click.echo(f"model: {result.run_dir / 'model.pt'}")


def register(main: click.Group) -> None:
    """Attach ``train`` to the gttnet command group."""
    main.add_command(train_command)
