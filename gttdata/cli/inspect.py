"""The ``gttdata inspect`` command: counts, shapes and statistics of a dataset directory or one shard."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from gttdata.cli import friendly_errors

if TYPE_CHECKING:
    from gttdata.manifest import Manifest

__all__ = ["format_summary", "inspect_cmd", "register"]


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def format_summary(manifest: Manifest) -> list[str]:
    """A table of the dataset per split: shards, samples, images, missing joints, noise and size."""
    head = f"{'split':<10} {'shards':>6} {'samples':>8} {'images':>9} {'img/smp':>8} {'miss %':>7} {'sigma px':>8} {'MiB':>9}"
    lines = [head, "-" * len(head)]
    rows = [(s, info, manifest.shards_of(s)) for s, info in manifest.splits.items()]
    rows.append(("total", {"statistics": manifest.statistics}, manifest.shards))
    for split, info, shards in rows:
        st = info["statistics"]
        sigma = st.get("sigma_px_mean")
        lines.append(
            f"{split:<10} {len(shards):>6} {st.get('n_samples', 0):>8} {st.get('n_images', 0):>9} "
            f"{st.get('images_per_sample_mean', 0):>8.1f} {_pct(st.get('missing_rate')):>7} "
            f"{'-' if sigma is None else f'{sigma:.2f}':>8} {sum(e.bytes for e in shards) / 2**20:>9.2f}"
        )
    return lines


def _describe_dataset(root: Path) -> None:
    from gttdata.manifest import MANIFEST_NAME, load_manifest, scan_shards
    from gttdata.shards.reader import ShardReader

    if not (root / MANIFEST_NAME).exists():
        shards, tmps = scan_shards(root)
        click.echo(f"{root}: no {MANIFEST_NAME} (incomplete, or build it with: gttdata manifest {root})")
        for p in shards:
            with ShardReader(p) as r:
                click.echo(
                    f"  {p.relative_to(root)}: {len(r)} samples, first_index {r.attrs.get('first_index')}"
                )
        for p in tmps:
            click.echo(f"  {p.relative_to(root)}: temporary file of an unfinished or killed run")
        return
    m = load_manifest(root)
    sk = m.skeleton or {}
    click.echo(f"dataset:   {m.name} ({root})")
    click.echo(
        f"schema:    {m.schema_version}, written by {m.generator}, git {m.git_sha or '-'}{' (dirty)' if m.git_dirty else ''}"
    )
    click.echo(f"recipe:    hash {m.recipe_hash[:16]}, seed {m.seed}")
    mixed: dict[str, int] = {}
    for info in m.splits.values():
        for name, count in (info.get("skeletons") or {}).items():
            mixed[name] = mixed.get(name, 0) + count
    if len(mixed) > 1:
        click.echo("skeletons: " + ", ".join(f"{n} x{c}" for n, c in sorted(mixed.items())))
    else:
        click.echo(f"skeleton:  {sk.get('name', '?')} ({len(sk.get('joint_names', ()))} joints)")
    rig = m.rig or {}
    click.echo(
        f"rig:       {rig.get('kind', '?')}, " + ", ".join(f"{k} {v}" for k, v in rig.items() if k != "kind")
    )
    click.echo(f"variants:  {', '.join(m.variants)}")
    for line in format_summary(m):
        click.echo(line)


def _describe_shard(path: Path, sample: int) -> None:
    from gttdata.shards.reader import ShardReader
    from gttdata.shards.schema import SAMPLES_GROUP, VARIANTS_GROUP

    with ShardReader(path) as r:
        a = r.attrs
        click.echo(f"shard:     {path}")
        click.echo(f"schema:    {a.get('schema_version')}, written by {a.get('generator', '-')}")
        click.echo(f"split:     {a.get('split')}, block {a.get('shard_index')} part {a.get('part')}")
        click.echo(
            f"samples:   {len(r)} (split indices {a.get('first_index')}..{a.get('first_index', 0) + len(r) - 1})"
        )
        click.echo(f"variants:  {', '.join(a.get('variants') or ['orig'])}")
        st = a.get("stats") or {}
        if st:
            miss = 1 - st["n_visible"] / max(st["n_joint_slots"], 1)
            click.echo(
                f"images:    {st['n_images']} ({st['n_images_min']}..{st['n_images_max']} per sample), missing {100 * miss:.1f} %"
            )
        if not len(r):
            return
        g = r.file[SAMPLES_GROUP][r._name(sample)]
        click.echo(f"sample {sample}: {g.attrs['name']} (motion {g.attrs['motion_name']})")
        groups = [("", g)] + [(f"{VARIANTS_GROUP}/{k}/", v) for k, v in g.get(VARIANTS_GROUP, {}).items()]
        for prefix, grp in groups:
            for name, ds in grp.items():
                if hasattr(ds, "shape"):
                    filt = ds.compression or "none"
                    click.echo(
                        f"  {prefix + name:<40} {str(ds.shape):<16} {str(ds.dtype):<8} {filt:<5} "
                        f"{ds.id.get_storage_size():>8} B"
                    )


@click.command("inspect")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--sample", type=int, default=0, show_default=True, help="Sample whose arrays are listed (shard files)."
)
@friendly_errors
def inspect_cmd(path: Path, sample: int) -> None:
    """Describe a dataset directory (manifest) or one shard file (attributes, arrays of one sample)."""
    if path.is_dir():
        _describe_dataset(path)
    else:
        _describe_shard(path, sample)


def register(main: click.Group) -> None:
    """Attach ``gttdata inspect``."""
    main.add_command(inspect_cmd)
