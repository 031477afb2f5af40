"""The ``gttnet export-json`` command: write one of our captures in the authors' GTT-Net JSON layout."""

from __future__ import annotations

import json

import click

from gttdata._cli_common import sample_options
from gttdata.errors import friendly_errors

__all__ = ["export_json_cmd", "register"]


@click.command("export-json")
@click.argument("input_path", metavar="INPUT", type=click.Path())
@sample_options("Sample index.", "Split of a recipe or dataset INPUT.", "Stored variant of the sample.")
@click.option(
    "--units",
    type=click.Choice(["m", "mm", "cm", "inch"]),
    default="m",
    show_default=True,
    help="Length unit of C, point3D and X_init in the file, recorded in its 'units' key "
    "(the authors' own files are in inches: --units inch).",
)
@click.option(
    "--limbs",
    "limb_format",
    type=click.Choice(["adjacency", "pairs"]),
    default="adjacency",
    show_default=True,
    help="limbSeq as the authors publish it (rows [joint, neighbour, ...]) or as one [joint, joint] pair per limb.",
)
@click.option(
    "--out", "out_path", type=click.Path(dir_okay=False), required=True, help="The .json file to write."
)
@click.option("--overwrite", is_flag=True, help="Replace an existing --out file.")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object describing the file written.")
@friendly_errors
def export_json_cmd(input_path, sample, split, variant, units, limb_format, out_path, overwrite, as_json):
    """Write a sample in the authors' GTT-Net JSON layout.

    Write sample I of INPUT (a shard file, a dataset folder or a generate recipe) in the authors' GTT-Net
    JSON layout: K = 0 with world rays, camID, t, C, point3D, limbSeq, X_init and rayDInd (docs/FORMAT.md).
    `gttnet reconstruct OUT.json` reads it back.

    \b
    Examples:
      gttnet export-json recipes/gttdata/tiny_topologies.yaml --split test --out /tmp/authors_layout.json --overwrite
      gttnet reconstruct /tmp/authors_layout.json --method dloe --sequencing none --json
    """
    from gttnet.cli.segment import load_capture
    from gttnet.io.gttnet_json import write_gttnet_json

    capture = load_capture(input_path, sample=sample, split=split, variant=variant)
    try:
        path = write_gttnet_json(capture, out_path, units=units, overwrite=overwrite, limb_format=limb_format)
    except FileExistsError as exc:
        raise click.ClickException(str(exc)) from None
    summary = {
        "out": str(path),
        "n_images": capture.n_images,
        "n_joints": capture.n_joints,
        "skeleton": capture.skeleton.name,
        "units": units,
    }
    if as_json:
        click.echo(json.dumps(summary))
    else:
        click.echo(
            f"{path}: {capture.n_images} images, {capture.n_joints} joints ({capture.skeleton.name}), "
            f"lengths in {units}"
        )


def register(main: click.Group) -> None:
    """Attach ``export-json`` to the ``gttnet`` command group."""
    main.add_command(export_json_cmd)
