"""The ``gttnet batch`` command: every trial of a Pose2Sim session, one reconstruct process each."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gttdata.errors import friendly_errors

__all__ = ["batch_cmd", "register"]


@click.command("batch", context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
@click.argument("session", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Results go to OUT/<trial>/result.<suffix>, each with its summary.json.",
)
@click.option(
    "--format",
    "suffix",
    type=click.Choice([".trc", ".c3d", ".csv", ".h5", ".npz"]),
    default=".trc",
    show_default=True,
    help="Result file type.",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Trials run at once (local processes).",
)
@click.option(
    "--part",
    default=None,
    metavar="I/N",
    help="Run every N-th trial starting at the I-th (1-based), e.g. a cluster array job's share: --part $SLURM_ARRAY_TASK_ID/8.",
)
@click.option(
    "--overwrite",
    is_flag=True,
    help="Run trials whose result exists again (default: skip them, so a batch resumes).",
)
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the summary (implies --no-progress).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object: a row per trial.")
@click.pass_context
@friendly_errors
def batch_cmd(ctx, session, out_dir, suffix, jobs, part, overwrite, progress, quiet, as_json):
    """Reconstruct every trial of a session.

    SESSION is a Pose2Sim session or participant folder whose trials (folders with pose/, pose-sync/ or
    pose-associated/) share one calibration. Each trial runs as `gttnet reconstruct TRIAL --out
    OUT/<trial>/result.trc`; options after `--` go to every one of them. A trial that fails is reported
    in one line and the others go on (exit 1 if any failed). A summary table follows: trial, status,
    cameras, images, recovered clock offsets and expected error.

    \b
    Examples:
      gttnet batch Session --out runs/session --jobs 2
      gttnet batch Session --out runs/session --part 2/4 -- --filter butterworth:6 --up y
    """
    from tqdm import tqdm

    from gttnet.batch import list_trials, parse_part, run_batch, summary_table

    try:
        i_n = parse_part(part)
        n_trials = len(list_trials(session)[i_n[0] - 1 :: i_n[1]])
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    bar = tqdm(total=n_trials, desc="trials", unit="trial", disable=not progress or quiet, leave=False)

    def done(r):
        bar.update(1)
        bar.set_postfix_str(f"{r.trial}: {r.status}")

    try:
        results = run_batch(
            session,
            out_dir,
            args=ctx.args,
            suffix=suffix,
            jobs=jobs,
            part=i_n,
            overwrite=overwrite,
            on_done=done,
        )
    finally:
        bar.close()
    if as_json:
        click.echo(
            json.dumps(
                {"session": str(session), "out": str(out_dir), "trials": [r.__dict__ for r in results]}
            )
        )
    else:
        click.echo(summary_table(results))
    failed = [r for r in results if r.status == "failed"]
    if failed:
        raise click.ClickException(f"{len(failed)} of {len(results)} trials failed (see the table)")


def register(main: click.Group) -> None:
    """Attach ``batch`` to the ``gttnet`` command group."""
    main.add_command(batch_cmd)
