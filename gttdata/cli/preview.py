"""The ``gttdata preview`` command: 2-D/3-D sanity previews of samples and plots of a dataset."""

from __future__ import annotations

from pathlib import Path

import click

from gttdata.errors import friendly_errors
from gttdata.threads import threads_option

__all__ = ["preview_cmd", "register"]


def _default_out(source: Path) -> Path:
    return source / "preview" if source.is_dir() else source.parent / "preview" / source.stem


def _check_3d() -> bool:
    """Whether 3-D views can be rendered; says why not on stderr."""
    from gttdata.preview._gl import PreviewDependencyError, RendererUnavailableError, offscreen_renderer

    try:
        offscreen_renderer(8, 8)
    except (RendererUnavailableError, PreviewDependencyError) as exc:
        click.echo(f"warning: 3-D views skipped: {exc}", err=True)
        return False
    return True


@click.command("preview")
@click.argument("source", metavar="DIR|SHARD", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--sample", "-s", "samples", type=int, multiple=True, help="Sample index (repeatable). [default: 0]"
)
@click.option(
    "--split",
    default="test",
    show_default=True,
    help="Split of a dataset directory DIR, also the one its dataset plots cover (a SHARD holds one split).",
)
@click.option("--variant", default="orig", show_default=True, help="Input variant to show.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Output directory [default: DIR/preview, or preview/<shard name> beside a SHARD].",
)
@click.option("--video", is_flag=True, help="Also write an MP4 of each sample in global time order.")
@click.option("--no-3d", "no_3d", is_flag=True, help="Skip the pyrender 3-D views.")
@click.option("--plots/--no-plots", default=True, show_default=True, help="Dataset plots (matplotlib).")
@click.option(
    "--max-samples",
    type=click.IntRange(min=1),
    default=1000,
    show_default=True,
    help="Samples read for the dataset statistics.",
)
@click.option(
    "--sheet-images",
    type=click.IntRange(min=1),
    default=48,
    show_default=True,
    help="Images (columns, first in time) per contact sheet.",
)
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print nothing but errors (implies --no-progress).")
@threads_option
@friendly_errors
def preview_cmd(
    source: Path,
    samples: tuple[int, ...],
    split: str | None,
    variant: str,
    out: Path | None,
    video: bool,
    no_3d: bool,
    plots: bool,
    max_samples: int,
    sheet_images: int,
    progress: bool,
    quiet: bool,
) -> None:
    """Write previews of samples of a dataset directory DIR (through its manifest) or of one SHARD file.

    Per sample: a cameras x time contact sheet of 2-D overlays, 3-D renders from every rig camera and an
    orbit camera, a timestamp raster and (--video) an MP4. For the whole source: timestamp raster,
    noise-sigma and missing-rate histograms, sequence lengths and motion sources.

    \b
    Examples:
      gttdata preview data/gttdata/default --sample 0 --video
      gttdata preview data/gttdata/default --split train --sample 0 --sample 2 --no-3d --out runs/preview
    """
    progress = progress and not quiet
    from gttdata._cli_common import check_shard_split
    from gttdata.preview._gl import PreviewDependencyError
    from gttdata.preview.plots import open_source, plot_dataset
    from gttdata.preview.render import render_samples

    check_shard_split(source, split)
    reader = open_source(source, split if source.is_dir() else None)
    out = _default_out(source) if out is None else out
    indices = samples or (0,)
    try:
        chosen = [reader.read_sample(i, variant) for i in indices]
    except (IndexError, KeyError) as exc:
        raise click.ClickException(str(exc).strip("'\"")) from exc
    render_3d = False if no_3d else _check_3d()
    written = render_samples(
        chosen,
        out,
        video=video,
        progress=progress,
        render_3d=render_3d,
        plots=plots,
        sheet_images=sheet_images,
    )
    if plots:
        try:
            written += plot_dataset(
                reader, out, sample=indices[0], max_samples=max_samples, progress=progress
            )
        except PreviewDependencyError as exc:
            click.echo(f"warning: plots skipped: {exc}", err=True)
    if not quiet:
        for path in written:
            click.echo(str(path))


def register(main: click.Group) -> None:
    """Attach ``gttdata preview``."""
    main.add_command(preview_cmd)
