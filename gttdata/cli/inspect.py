"""The ``gttdata inspect`` command: counts, shapes and statistics of a dataset directory or one shard."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from gttdata.errors import friendly_errors

if TYPE_CHECKING:
    from gttdata.manifest import Manifest

__all__ = ["dataset_summary", "field", "format_summary", "inspect_cmd", "plain", "register", "split_rows"]


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


def plain(value) -> str:
    """A recipe or attribute value as people write it: no Python reprs.

    ``{"uniform": [2, 8]}`` -> ``2-8 (uniform)``, ``{"choice": [3, 4]}`` -> ``3 | 4``, ``[1000, 1000]`` ->
    ``1000 x 1000``, ``True`` -> ``yes``, other dicts -> ``key value, ...``, floats without trailing zeros.
    """
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, dict):
        if set(value) == {"uniform"} and len(value["uniform"]) == 2:
            lo, hi = value["uniform"]
            return f"{plain(lo)}-{plain(hi)} (uniform)"
        if set(value) == {"choice"}:
            return " | ".join(plain(v) for v in value["choice"])
        return ", ".join(f"{k} {plain(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        if len(value) == 2 and all(isinstance(v, int) and not isinstance(v, bool) for v in value):
            return f"{value[0]} x {value[1]}"
        return ", ".join(plain(v) for v in value)
    return str(value)


_UNITS = {"_m": "m", "_px": "px", "_deg": "deg", "_hz": "Hz", "_s": "s"}

#: Keys whose name alone is ambiguous once the unit is moved out (two rig jitters would both read "jitter").
_LABELS = {"jitter_m": "centre jitter", "jitter_deg": "azimuth jitter", "jitter_s": "timing jitter"}


def field(key: str, value) -> str:
    """``radius_m, 3.0`` -> ``radius 3 m``: a key and its value, the unit suffix moved after the value.

    Example:
        >>> field("jitter_deg", 5.0), field("jitter_m", 0.1)
        ('azimuth jitter 5 deg', 'centre jitter 0.1 m')
    """
    for suffix, unit in _UNITS.items():
        if key.endswith(suffix):
            label = _LABELS.get(key, key[: -len(suffix)].replace("_", " "))
            return f"{label} {plain(value)} {unit}"
    return f"{key.replace('_', ' ')} {plain(value)}"


def split_rows(manifest: Manifest) -> dict[str, dict]:
    """Per split and ``total``: shards, samples, images, images per sample, missing rate, sigma, bytes."""
    rows = [(s, info, manifest.shards_of(s)) for s, info in manifest.splits.items()]
    rows.append(("total", {"statistics": manifest.statistics}, manifest.shards))
    out = {}
    for split, info, shards in rows:
        st = info["statistics"]
        out[split] = {
            "shards": len(shards),
            "samples": int(st.get("n_samples", 0)),
            "images": int(st.get("n_images", 0)),
            "images_per_sample": float(st.get("images_per_sample_mean", 0.0)),
            "missing_rate": st.get("missing_rate"),
            "sigma_px_mean": st.get("sigma_px_mean"),
            "bytes": int(sum(e.bytes for e in shards)),
        }
    return out


def format_summary(manifest: Manifest) -> list[str]:
    """A table of the dataset per split: shards, samples, images, missing joints, noise and size."""
    head = f"{'split':<10} {'shards':>6} {'samples':>8} {'images':>9} {'img/smp':>8} {'miss %':>7} {'sigma px':>8} {'MiB':>9}"
    lines = [head, "-" * len(head)]
    for split, r in split_rows(manifest).items():
        sigma = r["sigma_px_mean"]
        lines.append(
            f"{split:<10} {r['shards']:>6} {r['samples']:>8} {r['images']:>9} "
            f"{r['images_per_sample']:>8.1f} {_pct(r['missing_rate']):>7} "
            f"{'-' if sigma is None else f'{sigma:.2f}':>8} {r['bytes'] / 2**20:>9.2f}"
        )
    return lines


def dataset_summary(manifest: Manifest, root: Path) -> dict:
    """The JSON form of ``gttdata inspect DIR`` (and of ``gttdata generate --json``'s ``dataset``)."""
    sk = manifest.skeleton or {}
    return {
        "dataset": manifest.name,
        "path": str(root),
        "schema_version": manifest.schema_version,
        "generator": manifest.generator,
        "git_sha": manifest.git_sha,
        "git_dirty": manifest.git_dirty,
        "recipe_hash": manifest.recipe_hash,
        "seed": manifest.seed,
        "skeleton": {"name": sk.get("name"), "n_joints": len(sk.get("joint_names", ()))},
        "rig": manifest.rig or {},
        "variants": list(manifest.variants),
        "splits": split_rows(manifest),
    }


def _dataset_lines(root: Path) -> tuple[list[str], dict]:
    from gttdata.manifest import MANIFEST_NAME, load_manifest, scan_shards
    from gttdata.shards.reader import ShardReader

    if not (root / MANIFEST_NAME).exists():
        shards, tmps = scan_shards(root)
        lines = [f"{root}: no {MANIFEST_NAME} (incomplete, or build it with: gttdata manifest {root})"]
        found = []
        for p in shards:
            with ShardReader(p) as r:
                first = r.attrs.get("first_index")
                lines.append(f"  {p.relative_to(root)}: {len(r)} samples from split index {first}")
                found.append({"path": str(p.relative_to(root)), "samples": len(r), "first_index": first})
        for p in tmps:
            lines.append(f"  {p.relative_to(root)}: temporary file of an unfinished or killed run")
        data: dict[str, Any] = {
            "path": str(root),
            "complete": False,
            "shards": found,
            "temporary_files": [str(p.relative_to(root)) for p in tmps],
        }
        return lines, data
    m = load_manifest(root)
    data = dataset_summary(m, root)
    git = "-" if not m.git_sha else m.git_sha[:12] + (" (uncommitted changes)" if m.git_dirty else "")
    rig = dict(m.rig or {})
    kind = rig.pop("kind", "?")
    lines = [
        f"dataset    {m.name}  ({root})",
        f"written by {m.generator}, schema {m.schema_version}, git {git}",
        f"recipe     hash {m.recipe_hash[:16]}, seed {m.seed}",
        f"skeleton   {data['skeleton']['name'] or '?'}, {data['skeleton']['n_joints']} joints",
        f"rig        {kind}: " + ", ".join(field(k, v) for k, v in rig.items()),
        f"variants   {', '.join(m.variants)}",
        "",
        *format_summary(m),
    ]
    return lines, {"complete": True, **data}


def _shard_lines(path: Path, sample: int) -> tuple[list[str], dict]:
    from gttdata.shards.reader import ShardReader
    from gttdata.shards.schema import SAMPLES_GROUP, VARIANTS_GROUP

    with ShardReader(path) as r:
        a = r.attrs
        n = len(r)
        first = int(a.get("first_index", 0) or 0)
        lines = [
            f"shard      {path}",
            f"written by {a.get('generator', '-')}, schema {a.get('schema_version')}",
            f"split      {a.get('split')}, block {a.get('shard_index')}, part {a.get('part')}",
            f"samples    {n} (split indices {first}-{first + n - 1})" if n else "samples    0",
            f"variants   {', '.join(a.get('variants') or ['orig'])}",
        ]
        data = {
            "shard": str(path),
            "schema_version": a.get("schema_version"),
            "generator": a.get("generator"),
            "split": a.get("split"),
            "shard_index": a.get("shard_index"),
            "part": a.get("part"),
            "samples": n,
            "first_index": first,
            "variants": list(a.get("variants") or ["orig"]),
        }
        st = a.get("stats") or {}
        if st:
            miss = 1 - st["n_visible"] / max(st["n_joint_slots"], 1)
            lines.append(
                f"images     {st['n_images']} ({st['n_images_min']}-{st['n_images_max']} per sample), "
                f"{100 * miss:.1f} % of joints missing"
            )
            data.update(images=int(st["n_images"]), missing_rate=float(miss))
        if not n:
            return lines, data
        if not 0 <= sample < n:
            raise click.BadParameter(f"{path} holds samples 0-{n - 1}, got {sample}", param_hint="--sample")
        g = r.file[SAMPLES_GROUP][r._name(sample)]
        lines += ["", f"sample {sample}: {g.attrs['name']}, motion {g.attrs['motion_name']}"]
        lines.append(f"  {'array':<42} {'shape':<14} {'dtype':<8} {'filter':<6} {'stored':>9}")
        arrays = []
        groups = [("", g)] + [(f"{VARIANTS_GROUP}/{k}/", v) for k, v in g.get(VARIANTS_GROUP, {}).items()]
        for prefix, grp in groups:
            for name, ds in grp.items():
                if hasattr(ds, "shape"):
                    shape = " x ".join(str(d) for d in ds.shape) or "scalar"
                    size = ds.id.get_storage_size()
                    filt = ds.compression or "none"
                    lines.append(
                        f"  {prefix + name:<42} {shape:<14} {str(ds.dtype):<8} {filt:<6} {size:>7} B"
                    )
                    arrays.append(
                        {
                            "name": prefix + name,
                            "shape": list(ds.shape),
                            "dtype": str(ds.dtype),
                            "filter": filt,
                            "bytes": int(size),
                        }
                    )
        data["sample"] = {
            "index": sample,
            "name": str(g.attrs["name"]),
            "motion": str(g.attrs["motion_name"]),
            "arrays": arrays,
        }
    return lines, data


@click.command("inspect")
@click.argument("path", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--sample",
    "-s",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Sample whose arrays are listed (shard files).",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object instead of the text summary.")
@friendly_errors
def inspect_cmd(path: Path, sample: int, as_json: bool) -> None:
    """Describe a dataset directory (its manifest) or one shard file (attributes, arrays of one sample).

    \b
    Examples:
      gttdata inspect data/gttdata/default
      gttdata inspect data/gttdata/default/test/shard-00000.h5 --sample 2
      gttdata inspect data/gttdata/default --json
    """
    lines, data = _dataset_lines(path) if path.is_dir() else _shard_lines(path, sample)
    if as_json:
        click.echo(json.dumps(data))
        return
    for line in lines:
        click.echo(line)


def register(main: click.Group) -> None:
    """Attach ``gttdata inspect``."""
    main.add_command(inspect_cmd)
