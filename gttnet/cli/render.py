"""The ``gttnet render`` command: overlay videos, a 3-D animation and a timing plot of a reconstructed recording."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gttdata.errors import friendly_errors
from gttdata.threads import threads_option

__all__ = ["register", "render_cmd"]


@click.command("render")
@click.argument("result", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--project",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="Project file of the recording.",
)
@click.option("--calibration", type=click.Path(), default=None, help="Calibration of the recording.")
@click.option(
    "--keypoints",
    multiple=True,
    help="Keypoint sources as given to reconstruct (PATH or NAME=PATH; several may follow).",
)
@click.option("--fps", type=float, multiple=True, help="Frame rate(s), as given to reconstruct.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Output folder [default: RESULT's name + _render].",
)
@click.option("--overwrite", is_flag=True, help="Write into an existing, non-empty --out.")
@click.option(
    "--video-fps",
    type=click.FloatRange(min=0.1),
    default=None,
    help="Playback rate of the videos [default: each camera's rate].",
)
@click.option(
    "--width",
    "width_px",
    type=click.IntRange(min=64),
    default=640,
    show_default=True,
    help="Width of the per-camera videos, pixels.",
)
@click.option("--no-3d", "no_3d", is_flag=True, help="Skip the 3-D animation (pyrender).")
@click.option(
    "--max-frames",
    type=click.IntRange(min=1),
    default=None,
    help="At most this many 3-D animation frames (rows subsampled, with a warning) [default: every row].",
)
@click.option(
    "--input",
    "input_path",
    type=click.Path(exists=True, dir_okay=True),
    default=None,
    help="Capture file of a result made from one (.json, .mat, shard) [default: the source it records].",
)
@click.option(
    "--sample", type=click.IntRange(min=0), default=0, show_default=True, help="Sample of a shard input."
)
@click.option(
    "--units",
    type=click.Choice(["m", "mm", "cm", "inch"]),
    default=None,
    help="Length unit of a capture file that records none, as given to reconstruct.",
)
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the summary (implies --no-progress).")
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object: files written and reprojection error."
)
@click.argument("extra_keypoints", nargs=-1, type=click.Path())
@threads_option
@friendly_errors
def render_cmd(
    result,
    project,
    calibration,
    keypoints,
    fps,
    out,
    overwrite,
    video_fps,
    width_px,
    no_3d,
    max_frames,
    input_path,
    sample,
    units,
    progress,
    quiet,
    as_json,
    extra_keypoints,
):
    """Draw a reconstructed recording over its input.

    Draw a reconstructed recording: one MP4 per camera overlaying the reprojected 3-D joints (with
    lens distortion) on the input 2-D keypoints with per-joint reprojection error, a 3-D animation and
    a per-camera timing plot.

    RESULT is a .h5 written by `gttnet reconstruct` from a recording; the recording is reloaded from
    what the result stores unless --project or --calibration/--keypoints say otherwise. A result made from
    a capture file (GTT-Net JSON, .mat, a shard) gets the 3-D animation, the timing plot and the
    reprojection table (a capture file holds rays, not videos); its input is the source it records, or
    --input. The animation draws every image unless --max-frames subsamples it (with a warning).

    \b
    Examples:
      gttnet render runs/recording/result.h5 --out runs/recording/render
      gttnet render runs/recording/result.h5 --project runs/recording/project.toml --no-3d --json
      gttnet render result.h5 --input capture.json --out result_render
    """
    from gttdata.recording import load_project
    from gttnet.apps.render import is_recording_result, render_capture_result, render_result
    from gttnet.io.recording_input import spec_from_options

    try:
        from_recording = project is not None or calibration is not None or is_recording_result(result)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc

    spec = None
    if project is not None:
        spec = load_project(project)
    elif calibration is not None:
        spec = spec_from_options(calibration, list(keypoints) + list(extra_keypoints), fps=tuple(fps))
    elif keypoints or extra_keypoints:
        raise click.UsageError("--keypoints needs --calibration")
    out = out or result.with_name(result.stem + "_render")
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise click.ClickException(f"{out}: exists and is not empty; pass --overwrite to write into it")
    import logging

    from gttdata._cli_common import prints_warnings
    from gttnet.cli.reconstruct import _WarningLines

    warn = _WarningLines(logging.WARNING)
    names = ("gttdata", "gttnet.apps.render", "gttnet.io")
    loggers = [lg for lg in map(logging.getLogger, names) if not prints_warnings(lg)]  # none printed twice
    for lg in loggers:
        lg.addHandler(warn)
    try:
        if from_recording:
            written = render_result(
                result,
                out,
                spec=spec,
                video_fps=video_fps,
                width_px=width_px,
                animation=not no_3d,
                max_3d_frames=max_frames,
                progress=progress and not quiet,
            )
        else:
            written = render_capture_result(
                result,
                out,
                source=input_path,
                sample=sample,
                units=units,
                fps=video_fps or 30.0,
                animation=not no_3d,
                max_3d_frames=max_frames,
                progress=progress and not quiet,
            )
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    finally:
        for lg in loggers:
            lg.removeHandler(warn)
    import csv

    import numpy as np

    with open(written["reprojection_error"]) as fh:
        rows = [r for r in csv.DictReader(fh) if r["mean_px"]]
    n = np.array([int(r["n"]) for r in rows])
    mean = float(np.sum(n * np.array([float(r["mean_px"]) for r in rows])) / max(n.sum(), 1))
    summary = {
        "out": str(out),
        "files": sorted(p.name for p in written.values()),
        "reprojection_mean_px": round(mean, 3),
    }
    if as_json:
        click.echo(json.dumps(summary))
    else:
        click.echo(f"reprojection error {mean:.2f} px (mean) -> {out}: {', '.join(summary['files'])}")


def register(main: click.Group) -> None:
    """Attach ``render`` to the ``gttnet`` command group."""
    main.add_command(render_cmd)
