"""The ``gttdata motions`` commands: fetch, list and summarise mocap files."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import click

from gttdata.errors import GttDataError, friendly_errors

if TYPE_CHECKING:
    from gttdata.mocap.motion import Motion

__all__ = ["motions", "register", "standing_height_m", "summarise_motion"]


def standing_height_m(motion: Motion) -> float:
    """Standing height estimate: 95th percentile over frames of the joints' vertical extent, metres.

    Joints, not the body surface: the top joint is usually the head joint, so this sits below stature.
    """
    import numpy as np

    z = motion.positions[..., 2]
    return float(np.percentile(z.max(axis=1) - z.min(axis=1), 95))


def summarise_motion(motion: Motion) -> list[str]:
    """Human-readable summary lines (lengths in mm, as in every gtt report)."""
    pos = motion.positions
    lo, hi = pos.min(axis=(0, 1)), pos.max(axis=(0, 1))
    ext = (hi - lo) * 1000.0
    h = standing_height_m(motion)
    return [
        f"name: {motion.name} ({motion.provenance.get('format', '?')})",
        f"frames: {motion.n_frames}",
        f"fps: {motion.fps_hz:g}",
        f"joints: {motion.skeleton.n_joints} (skeleton {motion.skeleton.name})",
        f"duration: {motion.duration_s:.2f} s",
        f"extent: x {ext[0]:.0f} mm, y {ext[1]:.0f} mm, z {ext[2]:.0f} mm "
        f"(z from {lo[2] * 1000:.0f} to {hi[2] * 1000:.0f} mm)",
        f"standing height: {h:.2f} m ({h * 1000:.0f} mm, joints' vertical extent, 95th percentile)",
    ] + (
        [
            f"stature (rest pose incl. head-top and toe-tip end sites): {motion.provenance['rest_stature_m']:.2f} m"
        ]
        if "rest_stature_m" in motion.provenance
        else []
    )


@click.group("motions")
def motions() -> None:
    """Fetch, list and inspect mocap files (cache: $GTT_CACHE or ~/.cache/gtt/motions).

    \b
    Examples:
      gttdata motions fetch
      gttdata motions show 01_01.bvh
    """


@motions.command("fetch")
@click.option(
    "--out",
    "--dest",
    "dest",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Cache directory to fill [default: $GTT_CACHE or ~/.cache/gtt/motions].",
)
@click.option("--force", is_flag=True, help="Fetch every file again, even when a verified copy is cached.")
@friendly_errors
def fetch_cmd(dest: Path | None, force: bool) -> None:
    """Copy the CMU BVH clips and Vicon C3D trials from Debian packages into the cache.

    Every file is checked against its known SHA-256; a damaged cached copy is fetched again.

    \b
    Examples:
      gttdata motions fetch
      gttdata motions fetch --out /tmp/motions
    """
    from gttdata.mocap.fetch import fetch_motions

    paths = fetch_motions(dest, progress=click.echo, force=force)
    click.echo(f"{len(paths)} motion files in {paths[0].parent if paths else dest}")


@motions.command("list")
@click.option(
    "--cache",
    "--dest",
    "dest",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Cache directory to list [default: $GTT_CACHE or ~/.cache/gtt/motions].",
)
def list_cmd(dest: Path | None) -> None:
    """List the cached motion files with their frames, frame rate and joints.

    \b
    Examples:
      gttdata motions list
      gttdata motions list --cache /tmp/motions
    """
    from gttdata.mocap import load_motion
    from gttdata.mocap.fetch import cache_dir, list_cached

    cache = dest if dest is not None else cache_dir()
    files = list_cached(cache)
    if not files:
        click.echo(f"no motion files in {cache}; run 'gttdata motions fetch'")
        return
    click.echo(f"{'file':<24} {'frames':>7} {'fps':>6} {'joints':>6} {'MB':>6}")
    for p in files:
        size_mb = p.stat().st_size / 1e6
        try:
            with warnings.catch_warnings():
                warnings.simplefilter(
                    "ignore"
                )  # 'show' reports loader warnings; a listing stays one line per file
                m = load_motion(p)
        except (GttDataError, OSError) as exc:
            click.echo(f"{p.name:<24} unreadable ({exc}) {size_mb:.1f} MB")
            continue
        click.echo(f"{p.name:<24} {m.n_frames:>7} {m.fps_hz:>6g} {m.skeleton.n_joints:>6} {size_mb:>6.1f}")


@motions.command("show")
@click.argument("file", type=click.Path(path_type=Path))
@click.option(
    "--format", "fmt", default="auto", show_default=True, help="auto (by suffix) or bvh, amc, c3d, npz, hdf5."
)
@click.option("--scale", type=float, default=None, help="BVH only: metres per file unit.")
@friendly_errors
def show_cmd(file: Path, fmt: str, scale: float | None) -> None:
    """Summarise FILE (a path, or a name in the cache): frames, fps, joints, duration, extent, height.

    \b
    Examples:
      gttdata motions show 01_01.bvh
      gttdata motions show ~/.cache/gtt/motions/01_01.bvh
    """
    from gttdata.errors import GttDataError
    from gttdata.mocap import format_for_path, load_motion
    from gttdata.mocap.fetch import cache_dir, check_cached

    if not file.exists() and not file.is_absolute() and (cache_dir() / file).is_file():
        file = cache_dir() / file
    try:
        check_cached(file)  # shown either way (it is only read), but never passed off as the published clip
    except GttDataError as exc:
        click.echo(f"warning: {exc}", err=True)
    options = {}
    if scale is not None:
        if (format_for_path(file) if fmt == "auto" else fmt.lower()) != "bvh":
            raise click.UsageError("--scale applies to BVH files only (e.g. --scale 0.01 for centimetres)")
        options["scale"] = scale
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        motion = load_motion(file, fmt, **options)
    for w in caught:
        click.echo(f"warning: {w.message}", err=True)
    click.echo(f"file: {file}")
    for line in summarise_motion(motion):
        click.echo(line)


def register(main: click.Group) -> None:
    """Attach the ``motions`` group to the ``gttdata`` CLI."""
    main.add_command(motions)
