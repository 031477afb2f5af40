"""The ``gttnet reconstruct`` command: read an input file, run one method, write and report the result."""

from __future__ import annotations

import json
import logging

import click
import numpy as np

from gttdata.cli import friendly_errors

__all__ = ["register", "reconstruct_cmd"]

log = logging.getLogger(__name__)

_METHODS = ("pseudo", "dloe", "dct", "hpf", "gttnet")


def _report(loaded, rec) -> dict:
    from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm

    out = {
        "method": rec.method,
        "sequencing": rec.sequencing,
        "n_images": rec.n_images,
        "n_joints": rec.n_joints,
        "seconds": round(float(rec.seconds), 4),
    }
    gt = loaded.ground_truth
    if gt is not None:
        out["mpjpe_mm"] = round(mpjpe_mm(rec.points3d, gt.points3d), 4)
        if rec.order is not None and np.all(gt.global_order >= 0):
            out["order_kendall_tau"] = round(kendall_tau(rec.order, gt.global_order), 4)
    return out


@click.command("reconstruct")
@click.argument("input_path", metavar="INPUT", type=click.Path())
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["auto", "h5", "dloe-mat", "gttnet-json"]),
    default="auto",
    show_default=True,
    help="Input layout; auto picks it from the suffix (.h5, .mat, .json).",
)
@click.option(
    "--sample",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Sample index in a shard file (or over a dataset directory's splits).",
)
@click.option("--variant", default="orig", show_default=True, help="Input variant stored in a shard.")
@click.option(
    "--method", type=click.Choice(_METHODS), default="dloe", show_default=True, help="Reconstruction method."
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
    help="Length unit of a .mat/.json input, converted to metres [default: inch for those, m for shards].",
)
@click.option(
    "--out", "out_path", type=click.Path(dir_okay=False), default=None, help="Write the result (.h5 or .npz)."
)
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object with the run's summary on stdout."
)
@click.option(
    "--model", "model_path", type=click.Path(dir_okay=False), default=None, help="Trained model (gttnet)."
)
@click.option("--seed", type=int, default=None, help="Seed of the image shuffle under --sequencing none.")
@click.option(
    "--subjects",
    type=click.IntRange(1, 2),
    default=1,
    show_default=True,
    help="Subjects per image with no identity across images (2: joints are two stacked skeletons; "
    "their order is shuffled per image, then clustered by affinity).",
)
@friendly_errors
def reconstruct_cmd(
    input_path, fmt, sample, variant, method, sequencing, units, out_path, as_json, model_path, seed, subjects
):
    """Reconstruct the 3D joints of INPUT and recover the image order.

    INPUT is a shard file (.h5), a dataset directory of shards, a DLOE demo file (.mat) or a GTT-Net
    JSON file (.json).

    \b
    Example:
      gttnet reconstruct data/shard-00000.h5 --sample 3 --method dloe --sequencing partial \\
          --out rec.h5 --json
    """
    from gttnet.baselines.registry import check_sequencing, method_spec, reconstruct
    from gttnet.io import load_input
    from gttnet.io.output import write_reconstruction

    try:
        spec = method_spec(method)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--method") from exc
    try:
        loaded = load_input(
            input_path, fmt=fmt, sequencing=sequencing, sample=sample, variant=variant, units=units, seed=seed
        )
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    check_sequencing(loaded.observations, spec)
    options = {"model": model_path} if model_path is not None else {}
    if model_path is not None and method != "gttnet":
        raise click.BadParameter("--model applies only to --method gttnet", param_hint="--model")
    try:
        if subjects > 1:
            from gttnet.apps.multi_subject import reconstruct_loaded_subjects

            rec, summary = reconstruct_loaded_subjects(
                loaded, method=method, n_subjects=subjects, seed=seed or 0, **options
            )
        else:
            rec = reconstruct(loaded.observations, method, **options)
            summary = _report(loaded, rec)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    if out_path is not None:
        write_reconstruction(rec, out_path, image_index=loaded.image_index, source=loaded.source)
    if as_json:
        click.echo(json.dumps(summary))
        return
    parts = [f"{k}={v}" for k, v in summary.items()]
    click.echo(" ".join(parts) + (f" -> {out_path}" if out_path else ""))


def register(main: click.Group) -> None:
    """Attach ``reconstruct`` to the ``gttnet`` command group."""
    main.add_command(reconstruct_cmd)
