"""The ``gttdata generate`` command: recipe in, shards and manifest out, with a summary table."""

from __future__ import annotations

import dataclasses
import inspect
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gttdata.cli.inspect import (  # light: both import only click at module level
    dataset_summary,
    format_summary,
)
from gttdata.cli.verify import repo_manifests_dir
from gttdata.errors import friendly_errors
from gttdata.threads import threads_option

if TYPE_CHECKING:
    from gttdata.manifest import Manifest

__all__ = ["generate_cmd", "register"]


def _preview(manifest: Manifest, root: Path, n: int, *, quiet: bool = False) -> list[Path]:
    """Render the first ``n`` samples of the first split with gttdata.preview.render, when installed."""
    from gttdata.dataset import DatasetReader

    try:
        from gttdata.preview.render import render_samples
    except ImportError as exc:
        click.echo(f"warning: --preview: skipped, the preview renderer is not available ({exc})", err=True)
        return []
    split = next(iter(manifest.splits))
    reader = DatasetReader(root, split, manifest=manifest)
    samples = [reader.read_sample(i) for i in range(min(n, len(reader)))]
    out = root / "preview"
    try:
        inspect.signature(render_samples).bind(samples, out)
    except TypeError:
        click.echo(
            f"warning: --preview: skipped, render_samples{inspect.signature(render_samples)} does not take "
            "(samples, out_dir)",
            err=True,
        )
        return []
    written = [Path(p) for p in render_samples(samples, out, progress=not quiet) or []]
    if not quiet:
        click.echo(f"previews of {len(samples)} {split} sample{'s' if len(samples) > 1 else ''} in {out}:")
        for p in written:
            click.echo(f"  {p.name}")
    return written


@click.command("generate")
@click.argument("recipe_path", metavar="RECIPE", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("overrides", nargs=-1, metavar="[KEY=VALUE]...")
@click.option("--workers", "-j", type=click.IntRange(min=1), default=1, show_default=True, help="Processes.")
@click.option("--shard-range", default=None, metavar="A:B", help="Write only blocks A..B-1 (array jobs).")
@click.option("--resume", is_flag=True, help="Keep shards that verify, regenerate the rest.")
@click.option("--overwrite", is_flag=True, help="Delete the existing dataset in the output first.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Output directory (overrides output_dir).",
)
@click.option(
    "--register",
    "register_",
    is_flag=True,
    help="Copy the manifest to the repository's manifests/<name>.json.",
)
@click.option(
    "--preview", type=click.IntRange(min=0), default=0, metavar="N", help="Render N samples afterwards."
)
@click.option("--progress/--no-progress", default=True, show_default=True, help="Progress bar on stderr.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the summary table (implies --no-progress).")
@click.option(
    "--json",
    "as_json",
    is_flag=True,
    help="Print one JSON object (dataset summary, timing) and nothing else.",
)
@threads_option
@friendly_errors
def generate_cmd(
    recipe_path: Path,
    overrides: tuple[str, ...],
    workers: int,
    shard_range: str | None,
    resume: bool,
    overwrite: bool,
    out: Path | None,
    register_: bool,
    preview: int,
    progress: bool,
    quiet: bool,
    as_json: bool,
) -> None:
    """Simulate the captures of RECIPE into HDF5 shards, then write and verify manifest.json.

    An output that already holds a dataset is refused unless --resume (keep what verifies) or
    --overwrite (start again) is given; one process writes a folder at a time (--shard-range jobs may
    share it).

    \b
    Examples:
      gttdata generate recipes/gttdata/tiny.yaml --out /tmp/tiny
      gttdata generate recipes/gttdata/tiny.yaml seed=3 --workers 2 --out /tmp/tiny_seed3 --json
    """
    from gttdata.generation import generate_dataset, parse_shard_range, plan_blocks
    from gttdata.manifest import register_manifest
    from gttdata.recipe import load_recipe

    echo = (lambda *a, **k: None) if as_json else click.echo
    info = (lambda *a, **k: None) if (as_json or quiet) else click.echo
    progress = progress and not quiet
    recipe = load_recipe(recipe_path, overrides)
    if out is not None:
        recipe = dataclasses.replace(recipe, output_dir=str(out))
    blocks = plan_blocks(recipe)
    chosen = parse_shard_range(shard_range, len(blocks))
    n = sum(blocks[i].n_samples for i in chosen)
    info(
        f"{recipe.name}: {n} samples in {len(chosen)} of {len(blocks)} shards -> {recipe.output_dir} "
        f"({workers} worker{'s' if workers > 1 else ''}{', resume' if resume else ''})"
    )
    t0 = time.perf_counter()
    counts: dict[str, int] = {}
    manifest = generate_dataset(
        recipe,
        workers=workers,
        shard_range=shard_range,
        resume=resume,
        overwrite=overwrite,
        progress=progress,
        counts=counts,
    )
    seconds = time.perf_counter() - t0
    if manifest is None:
        if as_json:
            click.echo(
                json.dumps({"output_dir": str(recipe.output_dir), "complete": False, "seconds": seconds})
            )
            return
        click.echo(
            f"shards {chosen.start}:{chosen.stop} done in {seconds:.1f} s; other shards are missing, so the manifest "
            f"is written by the job that completes the dataset (or: gttdata manifest {recipe.output_dir})"
        )
        return
    for line in format_summary(manifest):
        echo(line)
    total = manifest.statistics
    n_written, kept = counts.get("samples_written", n), counts.get("samples_kept", 0)
    images_per_s = total.get("n_images", 0) * n_written / max(manifest.n_samples(), 1) / seconds
    root = Path(recipe.output_dir)
    rate = (
        f"{n_written / seconds:.1f} samples/s, {images_per_s:.0f} images/s"
        if n_written
        else "nothing to write"
    )
    echo(
        f"{seconds:.1f} s: {rate}{f'; {kept} samples kept (they verify)' if kept else ''}; "
        f"manifest {root / 'manifest.json'} verified"
    )
    registered = register_manifest(manifest, repo_manifests_dir(), location=root) if register_ else None
    if registered is not None:
        echo(f"registered {registered}")
    written = _preview(manifest, root, preview, quiet=as_json) if preview else []
    if as_json:
        report = {
            **dataset_summary(manifest, root),
            "samples_written": n_written,
            "samples_kept": kept,
            "seconds": round(seconds, 3),
            "samples_per_s": round(n_written / seconds, 3),
            "images_per_s": round(images_per_s, 1),
            "manifest": str(root / "manifest.json"),
            "registered": None if registered is None else str(registered),
            "previews": [str(p) for p in written],
        }
        click.echo(json.dumps(report))


def register(main: click.Group) -> None:
    """Attach ``gttdata generate``."""
    main.add_command(generate_cmd)
