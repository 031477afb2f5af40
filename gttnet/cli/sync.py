"""The ``gttnet sync`` command: recover each camera's clock from the skeletons and write a clocks file."""

from __future__ import annotations

import csv
import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gttdata._cli_common import check_shard_split, sample_options
from gttdata.errors import friendly_errors
from gttdata.threads import threads_option
from gttnet.cli._options import INPUT_FORMATS, STORED_SAMPLE_HELP, STORED_SPLIT_HELP
from gttnet.errors import GttNetError

if TYPE_CHECKING:
    import numpy as np

__all__ = ["parse_fps", "read_frame_times", "register", "sync_cmd"]

log = logging.getLogger(__name__)


def parse_fps(text: str | None) -> float | dict[int, float] | list[float] | None:
    """``"30"`` (every camera), ``"25,30,60"`` (by camera id) or ``"0=25,3=60"`` -> rates in Hz.

    Raises:
        click.BadParameter: Not a number, a list of numbers or ``id=rate`` pairs.

    Example:
        >>> parse_fps("25,30"), parse_fps("3=60")
        ([25.0, 30.0], {3: 60.0})
    """
    if text is None:
        return None
    items = [s.strip() for s in text.split(",") if s.strip()]
    try:
        if items and all("=" in s for s in items):
            return {int(k): float(v) for k, v in (s.split("=", 1) for s in items)}
        if len(items) == 1:
            return float(items[0])
        return [float(s) for s in items]
    except ValueError:
        raise click.BadParameter(
            f"expected Hz as '30', '25,30,60' (by camera id) or '0=25,1=30', got {text!r}", param_hint="--fps"
        ) from None


def read_frame_times(path: str | Path, cam_id: np.ndarray, stream_index: np.ndarray) -> np.ndarray:
    """Per-image times on each camera's own clock from a CSV with columns ``camera,frame,time_s``.

    ``frame`` is the image's index in its camera's stream (as the input numbers it); ``time_s`` its
    timestamp on that camera's clock, seconds (e.g. ffprobe's ``pts_time``). Extra rows are ignored.

    Returns:
        Times, shape ``(N,)``, in the input's image order.

    Raises:
        GttNetError: Missing column, unparsable value, or an image without a row (one line naming the file).
    """
    import numpy as np

    path = Path(path)
    table: dict[tuple[int, int], float] = {}
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        need = {"camera", "frame", "time_s"}
        if reader.fieldnames is None or not need <= set(reader.fieldnames):
            raise GttNetError(
                f"{path}: header: expected columns camera,frame,time_s, found {reader.fieldnames}"
            )
        for line, row in enumerate(reader, start=2):
            try:
                table[(int(row["camera"]), int(row["frame"]))] = float(row["time_s"])
            except (TypeError, ValueError):
                raise GttNetError(
                    f"{path}: line {line}: expected integer camera, integer frame and time_s in seconds, "
                    f"found {row['camera']!r}, {row['frame']!r}, {row['time_s']!r}"
                ) from None
    out = np.empty(cam_id.shape[0])
    for n, (c, k) in enumerate(zip(cam_id.tolist(), stream_index.tolist(), strict=True)):
        if (c, k) not in table:
            raise GttNetError(f"{path}: no row for camera {c} frame {k} (every image needs a time)")
        out[n] = table[(c, k)]
    return out


@click.command("sync")
@click.argument("input_paths", metavar="[INPUT]", nargs=-1, type=click.Path())
@click.option(
    "--calibration",
    type=click.Path(),
    default=None,
    help="Calibration of a recording (as gttnet reconstruct takes it).",
)
@click.option(
    "--keypoints",
    multiple=True,
    help="Keypoint source per camera, PATH or NAME=PATH (as gttnet reconstruct takes them).",
)
@click.option(
    "--timestamps",
    type=click.Path(),
    multiple=True,
    help="Per-frame timestamp CSV (ffprobe output) per camera, in the order of --keypoints.",
)
@click.option(
    "--skeleton",
    default=None,
    help="Keypoint set of a recording's detections (BODY_25B, BODY_25, HALPE_26..., docs/SKELETONS.md).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(INPUT_FORMATS),
    default="auto",
    show_default=True,
    help="Input layout; auto picks it from the suffix (.h5, .mat, .json).",
)
@sample_options(STORED_SAMPLE_HELP, STORED_SPLIT_HELP)
@click.option(
    "--units",
    type=click.Choice(["m", "mm", "cm", "inch"]),
    default=None,
    help="Length unit of a .mat/.json input [default: the unit the file records (our .json files do), "
    "else m with a warning; the authors' files are in inches]. Shards are metres.",
)
@click.option(
    "--fps",
    multiple=True,
    metavar="HZ",
    help="Nominal frame rate: one for all cameras ('30'), one per camera in order ('25,30,60' or the option "
    "repeated) or by camera ('0=25,2=60', or 'cam_0=25' for a recording), checked against the images (a rate "
    "they contradict is replaced, with a warning) [default: a recording's rates, else estimated from the "
    "images, relative to one camera, with a warning].",
)
@click.option(
    "--frame-times",
    type=click.Path(dir_okay=False, exists=True),
    default=None,
    help="CSV camera,frame,time_s: each frame's time on its camera's own clock (dropped frames show as gaps).",
)
@click.option(
    "--max-offset",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Largest offset searched between two cameras, seconds [default: any that leaves them overlapping].",
)
@click.option(
    "--drift/--no-drift", default=None, help="Fit clock drift [default: when a stream spans > 30 s]."
)
@click.option(
    "--out",
    "out_path",
    type=click.Path(dir_okay=False),
    default="clocks.json",
    show_default=True,
    help="Clocks file to write (JSON).",
)
@click.option("--overwrite", is_flag=True, help="Replace an existing clocks file.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object on stdout.")
@threads_option
@friendly_errors
def sync_cmd(
    input_paths,
    calibration,
    keypoints,
    timestamps,
    skeleton,
    fmt,
    sample,
    split,
    variant,
    units,
    fps,
    frame_times,
    max_offset,
    drift,
    out_path,
    overwrite,
    as_json,
):
    """Recover each camera's clock (offset, rate, drift, uncertainty) of INPUT from its 2-D skeletons.

    INPUT needs each camera's frames in order: a shard, a .mat/.json with stream order, or a recording (a
    project file, a Pose2Sim/anipose folder, or --calibration with --keypoints, as gttnet reconstruct takes
    them; its per-camera timestamp files or rates give each camera's own clock).
    Timestamps on a shared clock are never read. The clocks are written to --out and printed: frame k of camera c was taken at
    offset_s + (1 + drift_ppm 1e-6) k / rate_hz (or its --frame-times time instead of k / rate_hz).

    \b
    Examples:
      gttnet sync data/gttdata/default/test/shard-00000.h5 --sample 0 --out runs/clocks.json --json
      gttnet sync runs/recording/project.toml --out runs/recording/clocks.json --overwrite --json
    """
    import warnings

    import numpy as np

    from gttnet.io import load_input
    from gttnet.recording import load_view, recording_spec
    from gttnet.sync import clock_times, recover_clocks
    from gttnet.sync.rates import time_warnings

    out = Path(out_path)
    if out.exists() and not overwrite:
        raise click.ClickException(f"{out}: exists; pass --overwrite to replace it")
    names = None
    gt = None
    spec = recording_spec(
        input_paths,
        calibration=calibration,
        keypoints=keypoints,
        fps=fps,
        timestamps=timestamps,
        skeleton=skeleton,
    )
    input_path = input_paths[0] if len(input_paths) == 1 else ", ".join(input_paths)
    if spec is not None:  # a recording: its rates (the project's, Config.toml's or --fps) by camera
        from gttnet.cli.reconstruct import _WarningLines

        rec_log = logging.getLogger("gttdata.recording")  # a camera without usable detections: why
        lines = _WarningLines(logging.WARNING)
        rec_log.addHandler(lines)
        try:
            _, view, _ = load_view(spec, "partial", weights=False)
        finally:
            rec_log.removeHandler(lines)
        obs, names = view.observations, list(view.camera_names)
        known = np.asarray(view.fps, dtype=np.float64)
        rates = known.tolist() if known.size and np.all(np.isfinite(known)) else None
    else:
        if len(input_paths) != 1:
            raise click.UsageError(
                "give one INPUT file, a project file, a folder, or --calibration with --keypoints"
            )
        rates = parse_fps(",".join(fps) if fps else None)
        check_shard_split(input_path, split)
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", UserWarning)
                loaded = load_input(
                    input_path,
                    fmt=fmt,
                    sequencing="partial",
                    sample=sample,
                    variant=variant,
                    units=units,
                    split=split if Path(input_path).is_dir() else None,
                )
            for w in caught:
                click.echo(f"warning: {w.message}", err=True)
        except ValueError as exc:
            raise click.ClickException(str(exc)) from exc
        obs, gt = loaded.observations, loaded.ground_truth
    tau = None
    if frame_times is not None:
        tau = read_frame_times(frame_times, obs.cam_id, obs.stream_index)
    t0 = time.perf_counter()
    sync_log = logging.getLogger("gttnet.sync")
    held = logging.NullHandler()  # printed below, by camera name
    sync_log.addHandler(held)
    try:
        clocks = recover_clocks(
            obs, fps=rates, frame_times_s=tau, max_offset_s=max_offset, estimate_drift=drift
        )
    finally:
        sync_log.removeHandler(held)
    seconds = time.perf_counter() - t0
    checks = {"cameras_left_out": clocks.info.get("left_out", {}), "frame_rates": clocks.info.get("rates")}
    for line in time_warnings(checks, None if names is None else dict(enumerate(names))):
        click.echo(f"warning: {line}", err=True)
    clocks.save(out, overwrite=overwrite)
    report = {
        "input": str(input_path),
        "n_images": obs.n_images,
        "seconds": round(seconds, 4),
        "clocks_path": str(out),
        "cameras": clocks.to_dict()["cameras"],
        "cameras_left_out": checks["cameras_left_out"],
    }
    if names is not None:  # a recording: camera ids are positions in its camera list
        for row in report["cameras"]:
            row["name"] = names[row["camera"]]
    if gt is not None:  # evaluation only, after the estimate: the file happens to hold the true times
        err = clock_times(obs, clocks, frame_times_s=tau) - gt.timestamp_s
        err -= np.median(err)
        report["offset_error_frames"] = [
            round(float(np.median(err[obs.cam_id == c]) * r), 4)
            for c, r in zip(clocks.cameras, clocks.rate_hz, strict=True)
        ]
    if as_json:
        click.echo(json.dumps(report))
        return
    click.echo(f"{obs.n_images} images, {clocks.n_cameras} cameras, {seconds:.2f} s -> {out}")
    click.echo(f"{'camera':>6} {'offset s':>12} {'rate Hz':>9} {'drift ppm':>10} {'offset std ms':>14}")
    for c, o, r, d, s in zip(
        clocks.cameras, clocks.offset_s, clocks.rate_hz, clocks.drift_ppm, clocks.offset_std_s, strict=True
    ):
        label = names[int(c)] if names is not None else str(int(c))
        click.echo(f"{label:>6} {o:>12.6f} {r:>9.3f} {d:>10.1f} {1e3 * s:>14.3f}")
    if "offset_error_frames" in report:
        click.echo(
            "offset error vs the file's true times, frames: "
            + ", ".join(f"{e:+.3f}" for e in report["offset_error_frames"])
        )


def register(main: click.Group) -> None:
    """Attach ``sync`` to the ``gttnet`` command group."""
    main.add_command(sync_cmd)
