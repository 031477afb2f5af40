"""Test-time ablation: iterate GTT-Net on its own output, without sequencing (docs/MODEL_CARD.md).

Run:
    python benchmarks/ablation_iteration.py --recipe recipes/gttdata/paper.yaml --split test --n-seq 10
    python benchmarks/ablation_iteration.py --recipe recipes/gttdata/cmu.yaml --split test --n-seq 10

Variants, each run for ``--passes`` more passes of the same network after the first:
    feed    the previous pass's poses replace the pseudo-triangulated input structure (candidates kept);
    recand  the K candidates are rebuilt from how far each image's rays pass from the previous poses
            (symmetrised mean point-to-ray distance over the joints the image sees), input kept;
    both    both changes.
Prints a Markdown table of MPJPE (mm, mean and median over sequences) with DLOE and the first pass
measured on the same sequences. Ground truth is used for scoring only.
"""

from __future__ import annotations

import argparse
import dataclasses
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from gttdata.recipe import load_recipe  # noqa: E402
from gttnet.baselines._rays import ray_residuals  # noqa: E402
from gttnet.data import RecipeSource  # noqa: E402
from gttnet.evaluate.metrics import mpjpe_mm  # noqa: E402
from gttnet.geometry.neighbours import neighbourhoods  # noqa: E402
from gttnet.methods import reconstruct  # noqa: E402
from gttnet.model.inference import GTTNetReconstructor, prepare_inputs  # noqa: E402


def ray_cost(X: np.ndarray, obs) -> np.ndarray:
    """Symmetrised mean distance of image j's rays from image i's poses, shape ``(N, N)`` (metres).

    Row i is :func:`ray_residuals` of image i's joints against every image's rays, averaged over the joints
    each image sees; same-camera pairs are ``inf`` (never candidates).
    """
    centers, rays, vis = obs.centers(), obs.rays(), obs.visible
    seen = np.maximum(vis.sum(axis=1), 1)
    c = np.stack(
        [
            np.nan_to_num(ray_residuals(np.broadcast_to(x, X.shape), centers, rays, vis)).sum(1) / seen
            for x in X
        ]
    )
    c = c + c.T
    c[obs.cam_id[:, None] == obs.cam_id[None, :]] = np.inf
    return c


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recipe", default="recipes/gttdata/paper.yaml")
    ap.add_argument("--split", default="test")
    ap.add_argument("--n-seq", type=int, default=10)
    ap.add_argument("--passes", type=int, default=3)
    ap.add_argument("--model", default=None, help="model file (default: the bundled model)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    src = RecipeSource(load_recipe(args.recipe), args.split)
    net = GTTNetReconstructor(args.model, device="cpu").model
    res: dict[str, list[float]] = {}
    for i in range(args.n_seq):
        obs, gt = src.view(i * max(1, len(src) // args.n_seq), "none", "orig")
        res.setdefault("DLOE", []).append(mpjpe_mm(reconstruct(obs, "dloe").points3d, gt.points3d))
        seq = prepare_inputs(obs, k=net.config.k, candidates="dense")
        with torch.no_grad():
            first = net([seq], solve=True)[0].x_est.double()
        res.setdefault("GTT-Net, one pass", []).append(mpjpe_mm(first.numpy(), gt.points3d))
        for variant in ("feed", "recand", "both"):
            x = first
            for p in range(1, args.passes + 1):
                nbr = seq.nbr
                if variant != "feed":
                    cost = ray_cost(x.numpy(), obs)
                    nbr = torch.as_tensor(
                        neighbourhoods(cost, sequencing="none", cam_id=obs.cam_id, k=net.config.k)
                    )
                x_init = seq.x_init if variant == "recand" else x.float()
                with torch.no_grad():
                    x = net([dataclasses.replace(seq, x_init=x_init, nbr=nbr)], solve=True)[0].x_est.double()
                res.setdefault(f"{variant}, +{p} pass", []).append(mpjpe_mm(x.numpy(), gt.points3d))
    print(f"\n{args.recipe} {args.split}, {args.n_seq} sequences, no sequencing\n")
    print("| variant | MPJPE mean (mm) | median | min-max |\n|---|---|---|---|")
    for name, v in res.items():
        print(f"| {name} | {np.mean(v):.2f} | {np.median(v):.2f} | {np.min(v):.1f}-{np.max(v):.1f} |")


if __name__ == "__main__":
    main()
