"""Fault injection over a whole shard: flip one bit at every STEP-th byte and see what the deep check says.

Run:  python benchmarks/bench_shard_flips.py [--step 61] [--timing]

Generates ``recipes/gttdata/tiny.yaml`` into a temporary folder, then, for every ``--step``-th byte of
``train/shard-00000.h5``, flips bit 4 of that byte and indexes the file the way ``gttdata manifest`` does
(every attribute checksum and Fletcher-32 chunk). Each flip ends in one of:

* ``refused``: one ShardFormatError / ManifestError line naming the shard (what must happen to damage);
* ``unchanged``: accepted, and every sample, variant and root attribute reads back equal to the original
  (the byte was unused: padding or free space inside the file);
* ``CHANGED``: accepted, but some content differs (silent corruption; must be 0);
* ``crash``: any other exception (a traceback; must be 0).

``--timing`` also times the attribute checksum against the full deep check on a 128-sample shard.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from gttdata.errors import ManifestError, ShardFormatError
from gttdata.generation import generate_dataset
from gttdata.manifest import build_manifest
from gttdata.recipe import load_recipe
from gttdata.shards.digest import attrs_digest
from gttdata.shards.reader import ShardReader

REPO = Path(__file__).resolve().parents[1]
TINY = REPO / "recipes/gttdata/tiny.yaml"


def _content(path: Path) -> list:
    with ShardReader(path) as r:
        out: list = [dict(r.attrs)]
        for i in range(len(r)):
            for v in r.variants(i):
                s = r.read_sample(i, v)
                out.append({f.name: getattr(s, f.name) for f in dataclasses.fields(s)})
    return out


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b, equal_nan=True)
    return a == b


def flips(step: int, work: Path) -> dict[str, int]:
    """Counts of each outcome over every ``step``-th byte of the tiny train shard."""
    src_root = work / "src"
    generate_dataset(load_recipe(TINY, (f"output_dir={src_root}",)), progress=False)
    src = src_root / "train/shard-00000.h5"
    raw, ref = src.read_bytes(), _content(src)
    root = work / "flipped"
    (root / "train").mkdir(parents=True)
    path = root / "train/shard-00000.h5"
    counts = {"refused": 0, "unchanged": 0, "CHANGED": 0, "crash": 0}
    for off in range(0, len(raw), step):
        data = bytearray(raw)
        data[off] ^= 0x10
        path.write_bytes(bytes(data))
        try:
            with ShardReader(path) as reader:
                reader.check()
        except (ShardFormatError, ManifestError):
            counts["refused"] += 1
            continue
        except Exception as exc:  # noqa: BLE001 - counted, that is the point
            counts["crash"] += 1
            print(f"crash at byte {off}: {type(exc).__name__}: {exc}")
            continue
        if _same(ref, _content(path)):
            counts["unchanged"] += 1
        else:
            counts["CHANGED"] += 1
            print(f"silent change at byte {off}")
    print(f"{src.name}: {len(raw)} bytes, one flip every {step} bytes: {sum(counts.values())} flips")
    return counts


def timing(work: Path) -> None:
    """Seconds of :func:`attrs_digest` against the deep check on one 128-sample shard."""
    root = work / "big"
    over = (f"output_dir={root}", "splits.0.n_samples=128", "shard.samples_per_shard=128")
    generate_dataset(load_recipe(TINY, over), progress=False)
    build_manifest(root)  # warm the page cache
    path = root / "train/shard-00000.h5"
    with ShardReader(path) as r:
        t0 = time.perf_counter()
        attrs_digest(r.file)
        t_digest = time.perf_counter() - t0
        t0 = time.perf_counter()
        r.check()
        t_check = time.perf_counter() - t0
    print(
        f"128-sample shard: attrs_digest {t_digest * 1e3:.1f} ms, deep check (digest included) {t_check * 1e3:.1f} ms"
    )


def main() -> None:
    """Command line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step", type=int, default=61, help="Flip every STEP-th byte.")
    ap.add_argument("--timing", action="store_true", help="Also time the checksum on a 128-sample shard.")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        counts = flips(args.step, Path(tmp))
        print("  ".join(f"{k} {v}" for k, v in counts.items()))
        if args.timing:
            timing(Path(tmp))


if __name__ == "__main__":
    main()
