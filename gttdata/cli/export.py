"""The ``gttdata export`` command: a simulated capture as detector files, calibration, timestamps, project file."""

from __future__ import annotations

from pathlib import Path

import click

from gttdata._cli_common import check_shard_split, sample_options
from gttdata.errors import friendly_errors
from gttdata.threads import threads_option

__all__ = ["export_cmd", "register"]


def _read_sample(source: Path, split: str, sample: int, variant: str):
    from gttdata.dataset import DatasetReader
    from gttdata.shards.reader import ShardReader

    check_shard_split(source, split)
    reader = ShardReader(source) if source.is_file() else DatasetReader(source, split)
    try:
        n = len(reader) if source.is_dir() else None
        if n is not None and not 0 <= sample < n:
            raise click.ClickException(
                f"{source}: --sample must be in [0, {n}) for split {split!r}, got {sample}"
            )
        return reader.read_sample(sample, variant)
    except (IndexError, KeyError) as exc:
        raise click.ClickException(f"{source}: sample {sample}, variant {variant!r}: {exc}") from exc
    finally:
        reader.close()


@click.command("export")
@click.argument("source", metavar="DATASET|SHARD", type=click.Path(exists=True, path_type=Path))
@sample_options("Sample index.", "Split of a dataset directory.", "Input variant to export.")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["openpose", "dlc"]),
    default="openpose",
    show_default=True,
    help="Detector layout: OpenPose JSON folders or DeepLabCut CSV files, one per camera.",
)
@click.option(
    "--units",
    type=click.Choice(["m", "cm", "mm"]),
    default="m",
    show_default=True,
    help="Length unit of the calibration TOML's translations.",
)
@click.option(
    "--shared-clock", is_flag=True, help="Timestamps on one clock (a synchronized rig), not per camera."
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the confidence jitter.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), required=True, help="Output folder.")
@click.option(
    "--overwrite",
    is_flag=True,
    help="Replace an earlier export in --out (only the files it wrote; never other data).",
)
@threads_option
@friendly_errors
def export_cmd(source, split, sample, variant, fmt, units, shared_clock, seed, out, overwrite):
    """Write one simulated capture as a real recording would look.

    Per camera: detector files with realistic confidences and a timestamp CSV (as ffprobe writes it);
    plus calibration.toml (in --units), project.toml for `gttnet reconstruct`, and ground_truth.npz
    (for scoring only).

    \b
    Examples:
      gttdata export data/gttdata/tiny --split test --sample 0 --format openpose --units mm --out runs/recording
      gttdata export data/gttdata/default --sample 2 --format dlc --shared-clock --out runs/recording_dlc
    """
    from gttdata.export import export_capture

    cap = _read_sample(source, split, sample, variant)
    project = export_capture(
        cap,
        out,
        fmt=fmt,
        units=units,
        shared_clock=shared_clock,
        seed=seed,
        overwrite=overwrite,
        protect=[source],
    )
    click.echo(f"{cap.name}: {cap.n_cameras} cameras, {cap.n_images} images -> {project}")


def register(main: click.Group) -> None:
    """Attach ``export`` to the ``gttdata`` command group."""
    main.add_command(export_cmd)
