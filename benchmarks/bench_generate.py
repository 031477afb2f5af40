"""Generation throughput of ``generate_dataset`` (images/s per core) for a recipe, and its scaling from 1 to N workers.

Run:  python benchmarks/bench_generate.py [--recipe recipes/gttdata/paper.yaml] [--samples 64] [--workers 1 2]

The recipe's splits are replaced by one train split of ``--samples`` samples (its first split's motion
sources), packed 8 per shard so every worker has several blocks. Each row is a fresh run into a new
directory, timed end to end (process start-up, writing, manifest and its verification included); the
build/write row splits one in-process run into simulation and HDF5 writing.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import os
import tempfile
import time
from pathlib import Path

from gttdata.generate_plan import build_sample
from gttdata.generation import generate_dataset
from gttdata.recipe import load_recipe
from gttdata.shards import ShardWriter


def _digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.glob("*/*.h5")):
        h.update(p.read_bytes())
    return h.hexdigest()[:12]


def _recipe(path: str, samples: int, out: str):
    recipe = load_recipe(path)
    split = dataclasses.replace(recipe.splits[0], name="train", n_samples=samples)
    shard = dataclasses.replace(recipe.shard, samples_per_shard=8)
    return dataclasses.replace(recipe, splits=(split,), shard=shard, output_dir=out)


def _split_costs(recipe, n: int, tmp: Path) -> tuple[float, float, int]:
    """Seconds spent simulating and writing ``n`` samples in this process, and their image count."""
    t = time.perf_counter()
    groups = [build_sample(recipe, "train", i) for i in range(n)]
    build = time.perf_counter() - t
    t = time.perf_counter()
    with ShardWriter(tmp, split="train", max_samples=8, compression=recipe.shard.compression) as w:
        for g in groups:
            w.write(g)
    return build, time.perf_counter() - t, sum(g[0].n_images for g in groups)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = ap.parse_args()
    print(f"{args.recipe}: {args.samples} train samples, 8 per shard, {os.cpu_count()} CPUs visible")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for w in args.workers:
            recipe = _recipe(args.recipe, args.samples, f"{tmp}/w{w}")
            t = time.perf_counter()
            manifest = generate_dataset(recipe, workers=w, progress=False)
            sec = time.perf_counter() - t
            rows.append((w, manifest.statistics["n_images"], sec, _digest(Path(recipe.output_dir))))
        build, write, n_img = _split_costs(
            _recipe(args.recipe, args.samples, ""), min(args.samples, 16), Path(tmp, "split")
        )
    base = rows[0][1] / rows[0][2]
    print(
        f"| {'workers':>7} | {'images':>7} | {'seconds':>7} | {'images/s':>8} | {'images/s/core':>13} | {'speed-up':>8} | {'shards sha256':>13} |"
    )
    print("|---------|---------|---------|----------|---------------|----------|---------------|")
    for w, n, sec, digest in rows:
        rate = n / sec
        print(
            f"| {w:>7} | {n:>7} | {sec:>7.2f} | {rate:>8.0f} | {rate / w:>13.0f} | {rate / base:>8.2f} | {digest:>13} |"
        )
    print(
        f"in-process split over {min(args.samples, 16)} samples: simulation {n_img / build:.0f} images/s, "
        f"HDF5 writing {n_img / write:.0f} images/s ({100 * write / (build + write):.0f} % of the time)"
    )


if __name__ == "__main__":
    main()
