"""The ``gttdata verify`` and ``gttdata manifest`` commands: check a dataset against its manifest, or build one."""

from __future__ import annotations

import json
from pathlib import Path

import click

from gttdata.errors import friendly_errors

__all__ = ["manifest_cmd", "register", "repo_manifests_dir", "verify_cmd"]


def repo_manifests_dir() -> Path:
    """The repository's top-level ``manifests/`` folder (next to the ``gttdata`` package)."""
    import gttdata

    return Path(gttdata.__file__).resolve().parent.parent / "manifests"


@click.command("verify")
@click.argument("root", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--deep", is_flag=True, help="Also read every sample (chunk checksums, shapes).")
@click.option(
    "--json", "as_json", is_flag=True, help="Print one JSON object (ok, shards, samples, problems) on stdout."
)
@friendly_errors
def verify_cmd(root: Path, deep: bool, as_json: bool) -> None:
    """Check every shard of ROOT against manifest.json: presence, size, SHA-256, schema version.

    Exits with status 1 and one line per bad shard when anything differs (with --json: the object, whose
    ``problems`` lists those lines, and the same status).

    \b
    Examples:
      gttdata verify data/gttdata/default
      gttdata verify data/gttdata/default --deep
      gttdata verify data/gttdata/default --json
    """
    from gttdata.manifest import load_manifest, verify_manifest

    manifest = load_manifest(root)
    problems = verify_manifest(root, manifest, deep=deep)
    if as_json:
        report = {
            "root": str(root),
            "ok": not problems,
            "deep": deep,
            "shards": len(manifest.shards),
            "samples": manifest.n_samples(),
            "problems": list(problems),
        }
        click.echo(json.dumps(report))
        if problems:
            raise SystemExit(1)
        return
    for line in problems:
        click.echo(f"BAD {line}", err=True)
    if problems:
        raise click.ClickException(f"{root}: {len(problems)} problem(s) in {len(manifest.shards)} shards")
    click.echo(
        f"{root}: OK ({len(manifest.shards)} shards, {manifest.n_samples()} samples{', deep' if deep else ''})"
    )


@click.command("manifest")
@click.argument("root", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option(
    "--register", "register_", is_flag=True, help="Also copy it to the repository's manifests/<name>.json."
)
@friendly_errors
def manifest_cmd(root: Path, register_: bool) -> None:
    """Build ROOT/manifest.json from complete shards (e.g. after array jobs ran with --shard-range).

    \b
    Examples:
      gttdata generate recipes/gttdata/tiny.yaml --shard-range 0:2 --out /tmp/tiny_jobs
      gttdata generate recipes/gttdata/tiny.yaml --shard-range 2:3 --out /tmp/tiny_jobs
      gttdata manifest /tmp/tiny_jobs
    """
    from gttdata.manifest import build_manifest, register_manifest, verify_manifest, write_manifest

    manifest = build_manifest(root)
    path = write_manifest(manifest, root)
    problems = verify_manifest(root, manifest)
    if problems:
        raise click.ClickException(f"{path}: written but does not verify: {problems[0]}")
    click.echo(f"wrote {path} ({len(manifest.shards)} shards, {manifest.n_samples()} samples)")
    if register_:
        click.echo(f"registered {register_manifest(manifest, repo_manifests_dir(), location=root)}")


def register(main: click.Group) -> None:
    """Attach ``gttdata verify`` and ``gttdata manifest``."""
    main.add_command(verify_cmd)
    main.add_command(manifest_cmd)
