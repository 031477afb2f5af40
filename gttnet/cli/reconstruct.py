"""The ``gttnet reconstruct`` command: read an input file, run one method, write and report the result."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import click

from gttdata._cli_common import WarningLines, check_shard_split, sample_options
from gttdata.errors import RigError, friendly_errors
from gttdata.threads import threads_option
from gttnet.cli._options import INPUT_FORMATS, STORED_SAMPLE_HELP, STORED_SPLIT_HELP

__all__ = ["register", "reconstruct_cmd"]

log = logging.getLogger(__name__)


class MethodChoice(click.Choice):
    """``click.Choice`` over the method names (:func:`gttnet.methods.method_names`), read when first needed.

    The names come without importing any method's module (torch among them), which keeps ``--help`` and the
    classical methods' start-up fast; a name registered elsewhere loads the whole registry first.
    """

    def __init__(self) -> None:
        super().__init__((), case_sensitive=True)

    @property
    def choices(self) -> tuple[Any, ...]:
        import sys

        from gttnet._builtin_methods import BUILTIN_METHODS

        methods = sys.modules.get("gttnet.methods")  # loaded: names registered outside the built-ins too
        return tuple(sorted(BUILTIN_METHODS)) if methods is None else methods.method_names()

    @choices.setter
    def choices(self, value: Any) -> None:  # click.Choice.__init__ assigns it; the registry is the source
        pass

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        """The name as given; one not built in is looked up after every method module has registered."""
        if value not in self.choices:
            from gttnet.methods import available_methods

            available_methods()
        return super().convert(value, param, ctx)


def _window_arg(value: str) -> int | str | None:
    """``--window``: ``"auto"``, None for ``off``, or an image count >= 2."""
    if value in ("auto", "off"):
        return None if value == "off" else value
    try:
        n = int(value)
    except ValueError:
        n = -1
    if n < 2:
        raise click.BadParameter(
            f"expected auto, off or an integer >= 2, got {value!r}", param_hint="--window"
        )
    return n


def _method_default() -> str:
    from gttnet._builtin_methods import BUILTIN_METHODS

    return "auto" if "auto" in BUILTIN_METHODS else "dloe"


_WarningLines = WarningLines  # the name gttnet render and sync import


def _check_outs(out_paths, overwrite: bool) -> None:
    for out in out_paths:
        if Path(out).exists() and not overwrite:
            raise click.ClickException(f"{out}: exists; pass --overwrite to replace it")
        if Path(out).suffix.lower() not in (".trc", ".c3d", ".csv", ".h5", ".hdf5", ".npz"):
            raise click.BadParameter(
                f"{out}: suffix must be .trc, .c3d, .csv, .h5 or .npz", param_hint="--out"
            )


def _resolve_input(
    input_paths,
    weights,
    *,
    calibration,
    keypoints,
    fps,
    timestamps,
    clock,
    calibration_units,
    min_confidence,
    fmt,
    sample,
    variant,
    sequencing,
    units,
    seed,
    split=None,
    skeleton=None,
    n_subjects=1,
) -> list[dict]:
    """The run's input: a recording (calibration + keypoints, project file, Pose2Sim/anipose folder) or a file.

    A list with one input, except for a recording whose keypoint files hold several people: one input per
    person, the ``n_subjects`` most cameras agree on (:func:`gttnet.recording.choose_subjects`).
    """
    from gttnet.recording import load_views, recording_spec

    spec = recording_spec(
        input_paths,
        calibration=calibration,
        keypoints=keypoints,
        fps=fps,
        timestamps=timestamps,
        clock=clock,
        calibration_units=calibration_units,
        min_confidence=min_confidence,
        skeleton=skeleton,
    )
    if spec is not None:
        from gttnet.io.recording_input import spec_to_json

        handler = _WarningLines(logging.WARNING)
        names = ("gttdata.calibration", "gttdata.recording_folders", "gttdata.recording")
        loggers = [logging.getLogger(n) for n in names]
        for lg in loggers:
            lg.addHandler(handler)
        try:
            views = load_views(
                spec,
                sequencing,
                min_confidence=min_confidence,
                weights=weights,
                seed=seed or 0,
                n_subjects=n_subjects,
            )
        finally:
            for lg in loggers:
                lg.removeHandler(handler)
        return [
            {
                "loaded": None,
                "view": view,
                "gt": gt,
                "source": str(spec.calibration),
                "image_index": view.image_index,
                "recording_json": spec_to_json(spec),
                "skeleton": recording.skeleton,
                "recording": recording,
            }
            for recording, view, gt in views
        ]
    if len(input_paths) != 1:
        raise click.UsageError("give one INPUT file, a project file, or --calibration with --keypoints")
    import warnings

    from gttnet.io import load_input
    from gttnet.io.recording_input import view_of_loaded

    check_shard_split(input_paths[0], split)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", UserWarning)
            loaded = load_input(
                input_paths[0],
                fmt=fmt,
                sequencing=sequencing,
                sample=sample,
                variant=variant,
                units=units,
                seed=seed,
                split=split if Path(input_paths[0]).is_dir() else None,
            )
        for w in caught:
            click.echo(f"warning: {w.message}", err=True)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    except RigError as exc:  # bad cameras in the file: name it
        raise click.ClickException(f"{input_paths[0]}: {exc}") from exc
    return [
        {
            "loaded": loaded,
            "view": view_of_loaded(loaded),
            "gt": None if loaded.ground_truth is None else loaded.ground_truth.points3d,
            "source": loaded.source,
            "image_index": loaded.image_index,
            "recording_json": "",
        }
    ]


@click.command("reconstruct")
@click.argument("input_paths", metavar="[INPUT]", nargs=-1, type=click.Path())
@click.option(
    "--calibration",
    type=click.Path(),
    default=None,
    help="Calibration of a recording: aniposelib/Pose2Sim .toml, or EasyMocap intri.yml (extri.yml beside it).",
)
@click.option(
    "--keypoints",
    "keypoints",
    multiple=True,
    help="Keypoint source per camera: an OpenPose folder or a DeepLabCut .csv/.h5, SLEAP .slp or COCO/MMPose "
    ".json file, as PATH (camera named after it) or NAME=PATH. Several may follow one --keypoints.",
)
@click.option(
    "--fps",
    multiple=True,
    metavar="HZ",
    help="Frame rate, Hz: one for every camera ('30'), one per camera in order ('25,30,60' or the option "
    "repeated) or by camera ('cam_0=25,cam_2=60'). Clock recovery checks it against the images [default: "
    "the project's, Config.toml's or the videos', else timestamps, else estimated from the images with a "
    "warning].",
)
@click.option(
    "--skeleton",
    default=None,
    help="Keypoint set of the detections (BODY_25B, BODY_25, HALPE_26, COCO_133, BLAZEPOSE... docs/SKELETONS.md) "
    "[default: the project's or Config.toml's pose_model, else recognised from the joint count].",
)
@click.option(
    "--timestamps",
    type=click.Path(),
    multiple=True,
    help="Per-frame timestamp CSV (ffprobe output), once per camera, in the order of --keypoints.",
)
@click.option(
    "--clock",
    type=click.Choice(["per-camera", "shared"]),
    default="per-camera",
    show_default=True,
    help="Whether the cameras' timestamps share one clock (shared: full sequencing).",
)
@click.option(
    "--calibration-units",
    type=click.Choice(["m", "cm", "mm"]),
    default=None,
    help="Length unit of the calibration's translations [default: the file's, else detected with a warning].",
)
@click.option(
    "--min-confidence",
    type=click.FloatRange(0.0, 1.0),
    default=None,
    help="Detections scoring below this are missing; the rest weigh by their score [default: project's, or 0.1].",
)
@click.option(
    "--weights/--no-weights",
    default=True,
    show_default=True,
    help="Weigh each detection's ray residual by its confidence (recordings; DLOE pins rays; HPF and DCT use it).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(INPUT_FORMATS),
    default="auto",
    show_default=True,
    help="Layout of a single INPUT file; auto picks it from the suffix (.h5, .mat, .json).",
)
@sample_options(STORED_SAMPLE_HELP, STORED_SPLIT_HELP)
@click.option(
    "--method",
    type=MethodChoice(),
    default=None,
    help="Reconstruction method (see gttnet.methods.available_methods) [default: auto where "
    "available, else dloe].",
)
@click.option(
    "--sequencing",
    type=click.Choice(["none", "partial", "full"]),
    default=None,
    help="Sequencing the method may use [default: the richest the input supports].",
)
@click.option(
    "--units",
    type=click.Choice(["m", "mm", "cm", "inch"]),
    default=None,
    help="Length unit of a .mat/.json input, converted to metres [default: the unit the file records "
    "(our .json files do), else m with a warning; the authors' files are in inches]. Shards are metres.",
)
@click.option(
    "--out",
    "out_paths",
    type=click.Path(dir_okay=False),
    multiple=True,
    help="Write the result; the suffix picks the layout: .trc, .c3d, .csv (time order), .h5, .npz. Repeatable.",
)
@click.option("--overwrite", is_flag=True, help="Replace existing --out files.")
@click.option(
    "--export-keypoints",
    type=click.Path(file_okay=False),
    default=None,
    help="Also write each camera's 2-D keypoints re-timed onto the common clock (the .trc's frames) as "
    "OpenPose JSON folders, for Pose2Sim's or anipose's triangulation (needs times).",
)
@click.option(
    "--up",
    type=click.Choice(["y", "z"]),
    default="y",
    show_default=True,
    help="Up axis of a .trc (y: OpenSim's and Pose2Sim's, X Y Z = world y z x; z: the world's).",
)
@click.option(
    "--filter",
    "filter_spec",
    default=None,
    metavar="KIND:VALUE",
    help="Low-pass the uniform .trc/.c3d result: butterworth:HZ (zero-phase, cut-off), gaussian:SIGMA_FRAMES "
    "or median:WINDOW_FRAMES.",
)
@click.option(
    "--resample",
    "resample_hz",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    help="Uniform rate of the outputs, Hz (needs times): .trc/.c3d default to the fastest camera's rate, "
    ".csv to one row per image.",
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object with the run's summary on stdout."
)
@click.option(
    "--model", "model_path", type=click.Path(dir_okay=False), default=None, help="Trained model (gttnet)."
)
@click.option(
    "--refine/--no-refine",
    default=None,
    help="gttnet: one DLOE round after the network, or the network alone (default: the model's choice per "
    "sequencing, docs/MODEL_CARD.md).",
)
@click.option("--seed", type=int, default=None, help="Seed of the image shuffle under --sequencing none.")
@click.option(
    "--subjects",
    type=click.IntRange(1, 2),
    default=1,
    show_default=True,
    help="People to reconstruct. A recording: the N people most cameras agree on, associated across the "
    "unsynchronized cameras and through time, each written to OUT_p0, OUT_p1... A stored capture: 2 stacked "
    "skeletons per image with no identity across images (shuffled per image, then clustered by affinity).",
)
@click.option(
    "--window",
    default="auto",
    show_default=True,
    metavar="auto|off|N",
    help="Windowed reconstruction of long captures: N images per window (a quarter overlapping), auto "
    "(above 2,000 images 80 per camera; without sequencing 320 per camera, cut along the poses' order), "
    "or off (one piece).",
)
@click.option(
    "--progress/--no-progress", default=True, show_default=True, help="Window progress bar on stderr."
)
@click.option("--quiet", "-q", is_flag=True, help="Print only the result (implies --no-progress).")
@threads_option
@friendly_errors
def reconstruct_cmd(
    input_paths,
    calibration,
    keypoints,
    fps,
    skeleton,
    timestamps,
    clock,
    calibration_units,
    min_confidence,
    weights,
    fmt,
    sample,
    split,
    variant,
    method,
    sequencing,
    units,
    out_paths,
    overwrite,
    export_keypoints,
    up,
    filter_spec,
    resample_hz,
    as_json,
    model_path,
    refine,
    seed,
    subjects,
    window,
    progress,
    quiet,
):
    """Reconstruct the 3D joints of a recording or an INPUT file and recover the image order.

    A recording is a calibration plus one 2-D keypoint source per camera (--calibration, --keypoints,
    timing from --fps or --timestamps), or a project file (.toml/.yaml) listing them. INPUT may
    instead be a shard file (.h5), a dataset directory of shards, a DLOE demo file (.mat) or a GTT-Net
    JSON file (.json). The recording examples read the export of the README's walk-through
    (`gttdata export data/gttdata/tiny --split test --sample 0 --out runs/recording`).

    \b
    Examples:
      gttnet reconstruct runs/recording/project.toml --method dloe --out runs/recording/result.c3d --out runs/recording/result.h5 --json
      gttnet reconstruct --calibration runs/recording/calibration.toml --keypoints runs/recording/cam_0 runs/recording/cam_1 runs/recording/cam_2 --fps 10 --out runs/recording/result.trc
      gttnet reconstruct data/gttdata/tiny/test/shard-00000.h5 --sample 1 --method dloe --sequencing partial --out runs/rec.h5
    """
    from gttnet.methods import method_spec

    method = method or _method_default()
    if subjects > 1 and method == "auto":
        # the clustering needs an affinity over the virtual images; auto's order-free choice returns none
        method = "dloe"
    window_arg = _window_arg(window)
    try:
        spec_m = method_spec(method)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--method") from exc
    _check_outs(out_paths, overwrite)
    from gttnet.recording import parse_filter

    trc = {"up": up, "filter": parse_filter(filter_spec), "names": None}
    options = _gttnet_options(method, model_path, refine)
    resolve = dict(
        calibration=calibration,
        keypoints=keypoints,
        fps=fps,
        timestamps=timestamps,
        clock=clock,
        calibration_units=calibration_units,
        min_confidence=min_confidence,
        fmt=fmt,
        sample=sample,
        variant=variant,
        sequencing=sequencing,
        units=units,
        seed=seed,
        split=split,
        skeleton=skeleton,
    )
    run = dict(
        method=method,
        options=options,
        subjects=subjects,
        window_arg=window_arg,
        resample_hz=resample_hz,
        trc=trc,
        export_keypoints=export_keypoints,
        overwrite=overwrite,
        seed=seed,
        progress=progress and not quiet,
        quiet=quiet,
        sequencing_given=sequencing is not None,
    )
    inputs = _resolve_input(input_paths, weights, **resolve, n_subjects=subjects)
    inp = inputs[0]
    echo = lambda line: click.echo(line, err=True)  # noqa: E731
    if subjects > 1 and inp["loaded"] is None:
        # A recording with several people: one reconstruction per person (stable ids by cross-view
        # support), each written to its own files (result_p0.trc, result_p1.trc, ...).
        summaries = []
        for k, inp_k in enumerate(inputs):
            outs = [str(Path(o).with_name(f"{Path(o).stem}_p{k}{Path(o).suffix}")) for o in out_paths]
            export = None if export_keypoints is None else f"{export_keypoints}_p{k}"
            summary = _solve(inp_k, {**run, "subjects": 1, "export_keypoints": export}, spec_m, outs, echo)
            summaries.append({"subject": k, **summary})
        _print(summaries[0] | {"subjects": summaries}, as_json, [o for o in out_paths])
        return
    summary = _solve(inp, run, spec_m, list(out_paths), echo)
    _print(summary, as_json, out_paths)


def _print(summary: dict, as_json: bool, out_paths) -> None:
    """One JSON object, or per subject the self-assessment's ``quality:`` line then one ``key=value`` line."""
    from gttnet.recording import plain

    if as_json:
        click.echo(json.dumps(summary))
        return
    for one in summary["subjects"] if "subjects" in summary else [summary]:
        one = dict(one)
        quality = one.pop("quality", None)
        one.pop("auto", None)
        if quality is not None:  # before the summary line, which stays the last line of the output
            click.echo(
                f"quality: expected error ~{quality['expected_error_mm']:.1f} mm; {'; '.join(quality['reasons'])}"
            )
        parts = [f"{k}={plain(v)}" for k, v in one.items()]
        outs = out_paths if "subjects" not in summary else []
        click.echo(" ".join(parts) + (f" -> {', '.join(outs)}" if outs else ""))


def _solve(inp, run, spec_m, out_paths, echo) -> dict:
    """:func:`gttnet.pipeline.solve_and_write`, its refusals as one ``Error:`` line."""
    from gttnet.pipeline import solve_and_write

    if run["subjects"] > 1:
        from gttnet.apps.multi_subject import reconstruct_loaded_subjects

        run = {**run, "multi_subject": reconstruct_loaded_subjects}

    try:
        return solve_and_write(inp, run, spec_m, out_paths, echo, _WarningLines(logging.WARNING))
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc


def _gttnet_options(method: str, model_path: str | None, refine: bool | None) -> dict:
    """The method options of ``--model`` and ``--refine/--no-refine``, which apply to ``gttnet`` only."""
    options: dict[str, Any] = {}
    if model_path is not None:
        if method != "gttnet":
            raise click.BadParameter("--model applies only to --method gttnet", param_hint="--model")
        options["model"] = model_path
    if refine is not None:
        if method != "gttnet":
            raise click.BadParameter(
                "--refine/--no-refine apply only to --method gttnet", param_hint="--refine"
            )
        options["refine"] = refine
    return options


def register(main: click.Group) -> None:
    """Attach ``reconstruct`` to the ``gttnet`` command group."""
    main.add_command(reconstruct_cmd)
