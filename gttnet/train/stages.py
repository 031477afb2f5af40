"""Stage: one step of the training cascade (losses and weights, length, schedule, frozen parts)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

    from gttnet.model.network import GTTNet

__all__ = ["Stage", "LOSS_NAMES", "AFFINITY_TARGETS", "FREEZABLE", "SCHEDULES", "freeze_parts"]

#: Loss names a stage may weight: ℓ^AE, ℓ^A, ℓ^X, ℓ^S, ℓ^P.
LOSS_NAMES: tuple[str, ...] = ("autoencoding", "affinity", "structure", "smoothness", "pointnet")
#: A^G used by ℓ^A: ground-truth interpolation weights, 0/1 temporal adjacency, or observation-only labels.
AFFINITY_TARGETS: tuple[str, ...] = ("continuous", "binary", "pseudo")
#: Model parts a stage may freeze, each mapped to the modules of a :class:`GTTNet` it names (the one
#: source of truth: recipe validation checks names against its keys, :func:`freeze_parts` uses its values).
FREEZABLE: Mapping[str, Callable[[GTTNet], list[torch.nn.Module]]] = {
    "unet": lambda m: [m.unet],
    "encoder": lambda m: [m.unet.encoders, m.unet.enc_norms],
    "decoder": lambda m: [m.unet.decoders, m.unet.dec_norms],
    "pointnet": lambda m: [m.pointnet.point_mlp, m.pointnet.head] if m.pointnet is not None else [],
    "pointnet_decoders": lambda m: [m.pointnet.decoders] if m.pointnet is not None else [],
}
#: Learning-rate schedules.
SCHEDULES: tuple[str, ...] = ("plateau", "constant", "cosine")


@dataclass
class Stage:
    """One stage of the cascade; the loop runs stages in order with a fresh optimiser each.

    Ranges (refused with one line outside them): ``steps`` 1..10^9, ``epochs`` 1..10^6, ``lr`` in
    (0, 10], ``plateau_factor`` in (0, 1], ``plateau_patience`` and ``min_lr`` >= 0; loss weights finite.

    Args:
        name: Stage name (logs, checkpoints).
        losses: Weight of each loss in :data:`LOSS_NAMES`; losses not named are not computed.
        steps: Optimiser steps in this stage (exactly one of ``steps`` / ``epochs``).
        epochs: Passes over the training set in this stage.
        lr: Adam learning rate.
        schedule: One of :data:`SCHEDULES`. ``plateau`` multiplies the lr by ``plateau_factor`` when the
            validation loss has not improved for ``plateau_patience`` validations.
        plateau_factor: Factor of a plateau step (paper: halve).
        plateau_patience: Validations without improvement before a plateau step.
        min_lr: Lower bound of the learning rate.
        frozen: Parts in :data:`FREEZABLE` kept fixed in this stage.
        affinity_target: A^G for ℓ^A, one of :data:`AFFINITY_TARGETS`.
        norm: ``"mse"`` (squared Frobenius / count) or ``"fro"`` (non-squared, as the reference code).
    """

    name: str
    losses: dict[str, float]
    steps: int | None = field(default=None, metadata={"ge": 1, "le": 10**9})
    epochs: int | None = field(default=None, metadata={"ge": 1, "le": 10**6})
    lr: float = field(default=1e-3, metadata={"gt": 0, "le": 10})
    schedule: str = "plateau"
    plateau_factor: float = field(default=0.5, metadata={"gt": 0, "le": 1})
    plateau_patience: int = field(default=2, metadata={"ge": 0})
    min_lr: float = field(default=1e-6, metadata={"ge": 0})
    frozen: list[str] = field(default_factory=list)
    affinity_target: str = "continuous"
    norm: str = "mse"

    def __post_init__(self) -> None:
        bad = sorted(set(self.losses) - set(LOSS_NAMES))
        if bad:
            raise ValueError(f"stage {self.name!r}: unknown loss {bad[0]!r}; expected one of {LOSS_NAMES}")
        if not self.losses:
            raise ValueError(f"stage {self.name!r}: losses must name at least one of {LOSS_NAMES}")
        if (self.steps is None) == (self.epochs is None):
            raise ValueError(f"stage {self.name!r}: give exactly one of steps or epochs")
        if (self.steps or self.epochs or 0) < 1:
            raise ValueError(f"stage {self.name!r}: steps/epochs must be >= 1")
        for key, value, allowed in (
            ("schedule", self.schedule, SCHEDULES),
            ("affinity_target", self.affinity_target, AFFINITY_TARGETS),
            ("norm", self.norm, ("mse", "fro")),
        ):
            if value not in allowed:
                raise ValueError(f"stage {self.name!r}: {key} must be one of {allowed}, got {value!r}")
        bad = sorted(set(self.frozen) - set(FREEZABLE))
        if bad:
            raise ValueError(
                f"stage {self.name!r}: cannot freeze {bad[0]!r}; expected one of {tuple(FREEZABLE)}"
            )

    @property
    def needs_solver(self) -> bool:
        """Whether a loss of this stage needs the DLOE layer's X^E."""
        return any(self.losses.get(k, 0.0) != 0.0 for k in ("structure", "smoothness"))


def freeze_parts(model: GTTNet, frozen: list[str]) -> list[torch.nn.Parameter]:
    """Freeze the named parts (keys of :data:`FREEZABLE`), unfreeze the rest; returns the trainable parameters."""
    for p in model.parameters():
        p.requires_grad_(True)
    for name in frozen:
        for module in FREEZABLE[name](model):
            for p in module.parameters():
                p.requires_grad_(False)
    return [p for p in model.parameters() if p.requires_grad]
