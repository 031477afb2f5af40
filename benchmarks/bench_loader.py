"""Shard format benchmark: size, write time and random-access read speed per storage option, against plain .npy files.

Run:  python benchmarks/bench_loader.py [--samples 32] [--rounds 3] [--recipe recipes/gttdata/paper.yaml]

Samples are built from the recipe's train split (paper protocol: ~300 images x 31 joints, two variants).
Every option is written to a fresh directory, then all are read back in a random order, interleaved,
``--rounds`` times with a warm page cache, keeping each one's best round; the baseline loads the same original-capture arrays from one uncompressed ``.npy``
file per array. ``ratio`` = shard samples/s / npy samples/s (target >= 0.5 with compression on).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

import gttdata.shards.schema as schema
import gttdata.shards.writer as writer_mod
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe
from gttdata.shards import ShardReader, ShardWriter

ARRAYS = [f.name for f in schema.SAMPLE_FIELDS]


@contextmanager
def _policy(*, compress_all: bool = False, points_f64: bool = False, gzip_level: int | None = None):
    """Temporarily change the per-field storage policy of the writer (for measurement only)."""
    saved = (writer_mod.SAMPLE_FIELDS, writer_mod.VARIANT_FIELDS, schema._GZIP_LEVEL)

    def edit(f):
        if compress_all:
            f = dataclasses.replace(f, compress=True)
        if points_f64 and f.name == "points3d":
            f = dataclasses.replace(f, dtype="float64", lossy=False)
        return f

    writer_mod.SAMPLE_FIELDS = tuple(edit(f) for f in saved[0])
    writer_mod.VARIANT_FIELDS = tuple(edit(f) for f in saved[1])
    if gzip_level is not None:
        schema._GZIP_LEVEL = gzip_level
    try:
        yield
    finally:
        writer_mod.SAMPLE_FIELDS, writer_mod.VARIANT_FIELDS, schema._GZIP_LEVEL = saved


OPTIONS = {
    # name: (compression, policy kwargs); the first three are what the recipe's shard.compression selects.
    "none (recipe: none)": ("none", {}),
    "lzf selective (recipe: lzf)": ("lzf", {}),
    "gzip-4 selective (recipe: gzip)": ("gzip", {}),
    "gzip-4 selective, GT float64": ("gzip", {"points_f64": True}),
    "lzf all fields": ("lzf", {"compress_all": True}),
    "gzip-1 all fields": ("gzip", {"compress_all": True, "gzip_level": 1}),
    "gzip-4 all fields": ("gzip", {"compress_all": True}),
    "gzip-9 all fields": ("gzip", {"compress_all": True, "gzip_level": 9}),
    "gzip-4 all fields, GT float64": ("gzip", {"compress_all": True, "points_f64": True}),
}


def _read_shard(path: Path, order: np.ndarray, rounds: int) -> float:
    reader = ShardReader(path)
    len(reader)
    t = time.perf_counter()
    for _ in range(rounds):
        for i in order:
            reader.read_sample(int(i))
    return rounds * len(order) / (time.perf_counter() - t)


def _write_npy(root: Path, groups) -> None:
    for i, g in enumerate(groups):
        d = root / f"{i:06d}"
        d.mkdir(parents=True)
        for key in ARRAYS:
            np.save(d / f"{key}.npy", getattr(g[0], key))


def _read_npy(root: Path, order: np.ndarray, rounds: int) -> float:
    t = time.perf_counter()
    for _ in range(rounds):
        for i in order:
            d = root / f"{int(i):06d}"
            {key: np.load(d / f"{key}.npy") for key in ARRAYS}
    return rounds * len(order) / (time.perf_counter() - t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    recipe = load_recipe(args.recipe)
    t = time.perf_counter()
    groups = [build_sample(recipe, "train", i) for i in range(args.samples)]
    n_img = sum(g[0].n_images for g in groups) / len(groups)
    print(
        f"{args.samples} samples of {args.recipe} (train), {n_img:.0f} images x {groups[0][0].n_joints} joints, "
        f"variants {[s.variant for s in groups[0]]}, built in {time.perf_counter() - t:.1f} s"
    )
    order = np.random.default_rng(0).permutation(args.samples)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        _write_npy(tmp / "npy", groups)
        npy_bytes = sum(p.stat().st_size for p in (tmp / "npy").rglob("*.npy")) / args.samples
        written = {}
        for k, (name, (comp, policy)) in enumerate(OPTIONS.items()):
            out = tmp / f"opt{k}"
            with _policy(**policy):
                t = time.perf_counter()
                with ShardWriter(out, split="train", max_samples=10**6, compression=comp) as w:
                    for g in groups:
                        w.write(g)
                write_ms = (time.perf_counter() - t) / args.samples * 1e3
            written[name] = (out / "shard-00000.h5", write_ms)
        # Best of interleaved rounds: other load on the machine hits every option alike.
        best = {"npy": 0.0, **dict.fromkeys(written, 0.0)}
        for _ in range(args.rounds):
            best["npy"] = max(best["npy"], _read_npy(tmp / "npy", order, 1))
            for name, (path, _) in written.items():
                best[name] = max(best[name], _read_shard(path, order, 1))
        npy_rate = best["npy"]
        head = f"| {'storage':<32} | {'MB/sample':>9} | {'write ms/sample':>15} | {'read samples/s':>14} | {'ratio vs npy':>12} |"
        print(head)
        print("|" + "|".join("-" * (len(c)) for c in head.split("|")[1:-1]) + "|")
        print(
            f"| {'npy, orig arrays only':<32} | {npy_bytes / 1e6:>9.3f} | {'-':>15} | {npy_rate:>14.0f} | {1.0:>12.2f} |"
        )
        for name, (path, write_ms) in written.items():
            rate, size = best[name], os.path.getsize(path) / args.samples
            print(
                f"| {name:<32} | {size / 1e6:>9.3f} | {write_ms:>15.1f} | {rate:>14.0f} | {rate / npy_rate:>12.2f} |"
            )
    print("shard rows store orig + every variant; npy stores the orig arrays only (what one read returns).")


if __name__ == "__main__":
    main()
