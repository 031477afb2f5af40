"""The weighted loss of a stage over a batch of sequences, and validation metrics."""

from __future__ import annotations

import logging

import torch
from torch import nn

from gttnet import losses
from gttnet.data import TrainItem
from gttnet.model.network import GTTNet, SequenceOutput
from gttnet.train.stages import Stage

__all__ = ["stage_losses", "StepObjective"]

log = logging.getLogger(__name__)


def _affinity_target(stage: Stage, item: TrainItem, out: SequenceOutput, top_q: int) -> torch.Tensor:
    if stage.affinity_target == "continuous":
        return item.target_continuous
    if stage.affinity_target == "binary":
        return item.target_binary
    return losses.pseudo_affinity_targets(out.affinity.mask, q=top_q)


def stage_losses(
    stage: Stage, model: GTTNet, items: list[TrainItem], outputs: list[SequenceOutput]
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Weighted sum of the stage's losses, each averaged over the sequences.

    Args:
        stage: The stage (loss weights, affinity target, norm).
        model: The network (its config supplies Q and λ1).
        items: The sequences with their supervision.
        outputs: The network's outputs for ``items``.

    Returns:
        ``(total, parts)``: the scalar to minimise and each unweighted loss.
    """
    cfg = model.config
    parts: dict[str, torch.Tensor] = {}
    for name, weight in stage.losses.items():
        if weight == 0.0:
            continue
        vals = []
        for item, out in zip(items, outputs, strict=True):
            if name == "autoencoding":
                vals.append(losses.autoencoding_loss(out.ae_pairs, norm=stage.norm))
            elif name == "affinity":
                target = _affinity_target(stage, item, out, cfg.top_q)
                vals.append(losses.affinity_loss(out.affinity, target, norm=stage.norm))
            elif name in ("structure", "smoothness") and out.singular:
                continue  # a degenerate sample: its other losses still train (logged by the loop)
            elif name in ("structure", "smoothness") and out.x_est is None:
                raise ValueError(
                    f"stage {stage.name!r} weights the {name} loss but the DLOE layer did not run"
                )
            elif name == "structure":
                assert out.x_est is not None
                vals.append(losses.structure_loss(out.x_est, item.points3d, norm=stage.norm))
            elif name == "smoothness":
                assert out.x_est is not None
                vals.append(losses.smoothness_loss(out.a_sparse, out.x_est, lambda1=cfg.lambda1))
            elif getattr(model, "pointnet", None) is None:
                raise ValueError(
                    f"stage {stage.name!r} weights the pointnet loss but the model has no PointNet"
                )
            elif out.pointnet_recon is not None:
                # Only topologies with a decoder have a reconstruction target; augmented or unseen
                # topologies (joint subsets, merged joints, markers) train the other losses alone.
                vals.append(losses.pointnet_loss(out.pointnet_recon, item.inputs.x_init, norm=stage.norm))
        if vals:
            parts[name] = torch.stack([v.float() for v in vals]).mean()
    total = torch.zeros(())
    for k, v in parts.items():
        total = total + stage.losses[k] * v
    return total, parts


class StepObjective(nn.Module):
    """Wraps the network so one forward returns the stage loss (what DistributedDataParallel wraps).

    Args:
        model: The network.
    """

    def __init__(self, model: GTTNet) -> None:
        super().__init__()
        self.model = model

    def forward(self, items: list[TrainItem], stage: Stage) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Loss of ``stage`` on ``items`` (all sequences packed into one network call)."""
        outputs = self.model([it.inputs for it in items], solve=stage.needs_solver, skip_singular=True)
        for item, out in zip(items, outputs, strict=True):
            if out.singular:
                log.warning(
                    "stage %s: DLOE-layer system singular for a %d-image sequence; its structure losses are "
                    "skipped this step",
                    stage.name,
                    item.inputs.x_init.shape[0],
                )
        return stage_losses(stage, self.model, items, outputs)
