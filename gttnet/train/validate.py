"""Validation during training: stage loss, MPJPE of X^E and X_init, and precision of the kept affinities."""

from __future__ import annotations

import numpy as np
import torch

from gttnet.data import TrainItem
from gttnet.evaluate.metrics import mpjpe_mm
from gttnet.model.network import GTTNet
from gttnet.train.objective import stage_losses
from gttnet.train.stages import Stage

__all__ = ["validate"]


def _numpy(x: torch.Tensor) -> np.ndarray:
    return x.detach().double().cpu().numpy()


@torch.no_grad()
def validate(model: GTTNet, stage: Stage, items: list[TrainItem]) -> dict:
    """Stage loss, MPJPE of X^E and X_init (mean and median over sequences), and top-Q precision.

    ``kept_precision`` is the fraction of kept A^S entries that link true temporal neighbours (binary
    A^G): a solver-free measure of the learned affinity. The model is back in train mode on return.

    Args:
        model: The network.
        stage: The stage whose losses are reported.
        items: Validation sequences, on the model's device.

    Returns:
        ``loss``, ``mpjpe_mm``, ``mpjpe_median_mm``, ``mpjpe_init_mm``, ``mpjpe_init_median_mm``,
        ``kept_precision``, ``mpjpe_<condition>_mm`` and ``mpjpe_<condition>_median_mm`` per sequencing
        condition, and ``loss_<name>`` per stage loss (millimetres for MPJPE).
    """
    model.eval()
    totals, mpjpe, mpjpe_init, precision = [], [], [], []
    per_condition: dict[str, list[float]] = {}
    parts_sum: dict[str, float] = {}
    for item in items:
        out = model([item.inputs], solve=True)
        total, parts = stage_losses(stage, model, [item], out)
        totals.append(float(total))
        for k, v in parts.items():
            parts_sum[k] = parts_sum.get(k, 0.0) + float(v) / len(items)
        gt = _numpy(item.points3d)
        mpjpe.append(mpjpe_mm(_numpy(out[0].x_est), gt))
        per_condition.setdefault(item.condition or item.inputs.sequencing, []).append(mpjpe[-1])
        mpjpe_init.append(mpjpe_mm(_numpy(item.inputs.x_init), gt))
        aff = out[0].affinity
        real = aff.mask.gather(1, aff.keep)
        precision.append(float(item.target_binary.gather(1, aff.keep)[real].mean()) if real.any() else 0.0)
    model.train()
    return {
        "loss": float(np.mean(totals)),
        "mpjpe_mm": float(np.mean(mpjpe)),
        "mpjpe_median_mm": float(np.median(mpjpe)),
        "mpjpe_init_mm": float(np.mean(mpjpe_init)),
        "mpjpe_init_median_mm": float(np.median(mpjpe_init)),
        "kept_precision": float(np.mean(precision)),
        **{f"mpjpe_{c}_mm": float(np.mean(v)) for c, v in per_condition.items()},
        **{f"mpjpe_{c}_median_mm": float(np.median(v)) for c, v in per_condition.items()},
        **{f"loss_{k}": v for k, v in parts_sum.items()},
    }
