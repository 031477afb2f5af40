"""GTTNet: compose U-Net, affinity head and the DLOE layer into the learned trajectory triangulator."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from torch import nn

from gttnet.errors import SingularStructureError
from gttnet.model.affinity import AffinityHead, AffinityOutput, sparse_affinity
from gttnet.model.inputs import SequenceInput
from gttnet.model.patches import patch_index
from gttnet.model.pointnet import PointNetStream
from gttnet.model.unet import ContinuousConvUNet

__all__ = [
    "GTTNetConfig",
    "GTTNet",
    "SequenceOutput",
    "MODEL_BUILDERS",
    "register_builder",
    "build_model",
    "gttnet_tiny",
    "gttnet_base",
    "gttnet_pointnet",
]


@dataclass(frozen=True)
class GTTNetConfig:
    """Architecture and DLOE-layer settings of a GTT-Net; saved with every checkpoint.

    Args:
        n_joints: Joint count J of the input (ignored by the PointNet variant).
        widths: Encoder widths in pseudo-points after the input (paper: 16, 8, 4, 4).
        hidden: Hidden width of the continuous-convolution weight MLPs.
        k: Neighbours per image K (paper: 20).
        affinity_mode: ``"paper"`` or ``"reference"`` (see :class:`AffinityHead`).
        top_q: Affinities kept per row Q (paper: 2).
        lambda1: Weight of the compactness term in the DLOE layer (GTT-Net training: 0.1).
        lambda2: Ray-term weight of the DLOE layer; None = the solver's default (rays pinned).
        pointnet: Feed the U-Net PointNet virtual points instead of the joints (cross-domain variant).
        n_virtual: PointNet virtual points V.
        domains: Joint count per domain (topology name), one PointNet decoder each.
        prior_weight: Relative ridge of the DLOE layer toward X_init (keeps a top-Q graph whose component
            sees a joint along one ray direction solvable); None: no ridge (singular graphs then raise).
        solver_method: DLOE-layer linear solver, ``"auto"``, ``"dense"`` (batched Cholesky, GPU) or
            ``"sparse"`` (SuperLU on CPU; about 6x faster than dense there at N = 177 on 2 cores).
        slot_rank: Give the slot-mixing MLPs each neighbour's rank (cost or time order); off in the paper.
    """

    n_joints: int = 31
    widths: tuple[int, ...] = (16, 8, 4, 4)
    hidden: int = 16
    k: int = 20
    affinity_mode: str = "paper"
    top_q: int = 2
    lambda1: float = 0.1
    lambda2: float | None = None
    pointnet: bool = False
    n_virtual: int = 10
    domains: dict[str, int] = field(default_factory=dict)
    prior_weight: float | None = 1e-6
    solver_method: str = "auto"
    slot_rank: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "widths", tuple(int(w) for w in self.widths))
        if self.k < 1 or self.top_q < 1 or self.top_q > self.k:
            raise ValueError(f"need 1 <= top_q <= k, got k={self.k}, top_q={self.top_q}")
        if self.pointnet and not self.domains:
            raise ValueError("the PointNet variant needs at least one domain, e.g. domains={'cmu31': 31}")


@dataclass
class SequenceOutput:
    """Network outputs for one sequence.

    Args:
        affinity: A^D over the neighbourhood and the kept entries (:class:`AffinityOutput`), rows of this
            sequence only.
        a_sparse: A^S, shape ``(N, N)``.
        x_est: X^E from the DLOE layer in world, metres, shape ``(N, J, 3)``; None when not solved.
        singular: The DLOE layer ran but its system was singular (``forward(skip_singular=True)`` only);
            ``x_est`` is then None.
        ae_pairs: ``(decoder, encoder)`` feature pairs for ℓ^AE, each shape ``(N, P_i, 3)``.
        pointnet_recon: PointNet reconstruction of X_init, shape ``(N, J, 3)``; None without PointNet.
    """

    affinity: AffinityOutput
    a_sparse: torch.Tensor
    x_est: torch.Tensor | None
    ae_pairs: list[tuple[torch.Tensor, torch.Tensor]]
    pointnet_recon: torch.Tensor | None
    singular: bool = False


def _default_solver() -> Callable[..., torch.Tensor]:
    from gttnet.solvers.xstep import solve_structure

    return solve_structure


def _normalise(x: torch.Tensor) -> torch.Tensor:
    """Centre a sequence on its centroid and divide by its RMS radius (translation/scale invariance)."""
    xc = x - x.mean(dim=(0, 1), keepdim=True)
    return xc / torch.sqrt(xc.pow(2).sum(-1).mean() + 1e-12)


class GTTNet(nn.Module):
    """GTT-Net: X_init + neighbourhoods → U-Net latent → A^D → top-Q A^S → DLOE layer → X^E.

    The forward pass takes a list of sequences and packs them into one batch of images for the U-Net (the
    neighbourhoods never cross sequences); the DLOE layer then runs per sequence. Only
    :class:`SequenceInput` reaches the network: it is built from observations, never ground truth.

    Args:
        config: :class:`GTTNetConfig`.
        solver: The DLOE layer ``solve(A, centers, rays, visible, *, lambda1, lambda2) -> X``; default
            :func:`gttnet.solvers.xstep.solve_structure`.
    """

    config: GTTNetConfig

    def __init__(self, config: GTTNetConfig, *, solver: Callable[..., torch.Tensor] | None = None) -> None:
        super().__init__()
        self.config = config
        in_points = config.n_virtual if config.pointnet else config.n_joints
        self.pointnet = (
            PointNetStream(config.domains, n_virtual=config.n_virtual) if config.pointnet else None
        )
        self.unet = ContinuousConvUNet(
            in_points, config.widths, n_slots=config.k + 1, hidden=config.hidden, slot_rank=config.slot_rank
        )
        self.affinity = AffinityHead(config.affinity_mode, top_q=config.top_q)
        self._solver = solver

    def _inputs(self, seq: SequenceInput) -> tuple[torch.Tensor, torch.Tensor | None]:
        if self.pointnet is None:
            if seq.x_init.shape[1] != self.config.n_joints:
                raise ValueError(
                    f"model expects {self.config.n_joints} joints, got {seq.x_init.shape[1]}; "
                    "use the PointNet variant for other skeletons"
                )
            return _normalise(seq.x_init), None
        virtual, latent, bary = self.pointnet(seq.x_init, seq.visible)
        recon = (
            self.pointnet.decode(latent, bary, seq.domain) if seq.domain in self.pointnet.decoders else None
        )
        return _normalise(virtual), recon

    def forward(
        self,
        batch: list[SequenceInput],
        *,
        solve: bool = True,
        top_q: int | None = None,
        lambda2: float | np.ndarray | None = None,
        decode: bool = True,
        skip_singular: bool = False,
    ) -> list[SequenceOutput]:
        """Run the network on a list of sequences.

        Args:
            batch: Sequences (each with its own N).
            solve: Run the DLOE layer (needed for ℓ^X, ℓ^S and inference; stage 1 skips it).
            top_q: Affinities kept per row for this call; None = ``config.top_q``.
            lambda2: Ray weight of the DLOE layer for this call; None = ``config.lambda2``.
            decode: Run the U-Net's decoder, whose outputs feed only the autoencoding loss (``ae_pairs``);
                inference passes False (same affinities and structure, half the layers).
            skip_singular: A sequence whose DLOE-layer system is singular gets ``x_est=None`` and
                ``singular=True`` instead of raising :class:`~gttnet.errors.SingularStructureError`
                (training: one degenerate sample must not end a run).

        Returns:
            One :class:`SequenceOutput` per sequence (``ae_pairs`` empty without the decoder).
        """
        if not batch:
            raise ValueError("batch must hold at least one sequence")
        xs, recons, nbrs, segs, sizes = [], [], [], [], []
        offset = 0
        for s, seq in enumerate(batch):
            x0, recon = self._inputs(seq)
            n = x0.shape[0]
            if seq.nbr.shape[1] != self.config.k:
                raise ValueError(f"model expects K={self.config.k} neighbours, got {seq.nbr.shape[1]}")
            xs.append(x0)
            recons.append(recon)
            nbrs.append(torch.where(seq.nbr >= 0, seq.nbr.long() + offset, -1))
            segs.append(torch.full((n,), s, dtype=torch.long, device=x0.device))
            sizes.append(n)
            offset += n
        x = torch.cat(xs)
        index, mask = patch_index(torch.cat(nbrs))
        seg = torch.cat(segs)
        u = self.unet(
            x, index, mask, seg, len(batch), decode=decode, slots=self.config.affinity_mode == "reference"
        )
        aff = self.affinity(u.bottleneck, u.bottleneck_slots, index, mask, top_q=top_q)
        outs, start = [], 0
        for seq, n, recon in zip(batch, sizes, recons, strict=True):
            sl = slice(start, start + n)
            start += n
            a = AffinityOutput(values=aff.values[sl], mask=aff.mask[sl], keep=aff.keep[sl], kept=aff.kept[sl])
            if seq.sequencing == "full" and seq.chain is not None:
                # The timestamps are given: the solver interpolates each image between its time
                # neighbours instead of trusting the learned affinity (measured better than both
                # combined and than DLOE; see SequenceInput.chain).
                a_sparse = seq.chain.to(a.kept.dtype)
            else:
                chain = seq.chain if seq.sequencing == "partial" else None
                a_sparse = sparse_affinity(a.kept, a.keep, seq.nbr, chain=chain)
            x_est, singular = None, False
            if solve:
                try:
                    x_est = self.solve(a_sparse, seq, lambda2=lambda2)
                except SingularStructureError:
                    if not skip_singular:
                        raise
                    singular = True
            pairs = [(d[sl], e[sl]) for d, e in u.pairs]
            outs.append(SequenceOutput(a, a_sparse, x_est, pairs, recon, singular))
        return outs

    def solve(
        self, a_sparse: torch.Tensor, seq: SequenceInput, *, lambda2: float | np.ndarray | None = None
    ) -> torch.Tensor:
        """DLOE layer: structure from the affinity (float32 at least, outside autocast).

        Args:
            a_sparse: A^S, shape ``(N, N)``.
            seq: The sequence's inputs (rays and centres in world).
            lambda2: Ray weight, a number or one per image ``(N,)``; None = ``config.lambda2``.

        Returns:
            X^E in world, metres, shape ``(N, J, 3)``.
        """
        solver = self._solver if self._solver is not None else _default_solver()
        dtype = torch.promote_types(seq.rays.dtype, torch.float32)
        prior = {}
        if self.config.prior_weight is not None:
            prior = {"x_prior": seq.x_init.detach().to(dtype), "prior_weight": self.config.prior_weight}
        with torch.autocast(device_type=a_sparse.device.type, enabled=False):
            return solver(
                a_sparse.to(dtype),
                seq.centers.to(dtype),
                seq.rays.to(dtype),
                seq.visible,
                lambda1=self.config.lambda1,
                lambda2=self.config.lambda2 if lambda2 is None else _ray_weight(lambda2),
                method=self.config.solver_method,
                **prior,
            )


def _ray_weight(lambda2: float | np.ndarray) -> float | np.ndarray:
    """A ray weight as the solver takes it: a float, or a float64 array of one weight per image."""
    arr = np.asarray(lambda2, dtype=np.float64)
    return float(arr) if arr.ndim == 0 else arr


MODEL_BUILDERS: dict[str, Callable[..., GTTNet]] = {}


def register_builder(name: str) -> Callable[[Callable[..., GTTNet]], Callable[..., GTTNet]]:
    """Decorator registering a model builder under ``name`` (recipes name builders, not import paths)."""

    def deco(fn: Callable[..., GTTNet]) -> Callable[..., GTTNet]:
        MODEL_BUILDERS[name] = fn
        return fn

    return deco


def build_model(name: str, **overrides) -> GTTNet:
    """Build a registered model with config overrides (unknown keys raise ValueError)."""
    if name not in MODEL_BUILDERS:
        raise ValueError(f"unknown model builder {name!r}; known: {sorted(MODEL_BUILDERS)}")
    known = {f.name for f in dataclasses.fields(GTTNetConfig)}
    bad = sorted(set(overrides) - known)
    if bad:
        raise ValueError(f"unknown model setting(s) {bad}; known: {sorted(known)}")
    return MODEL_BUILDERS[name](**overrides)


@register_builder("gttnet_tiny")
def gttnet_tiny(**overrides) -> GTTNet:
    """A small GTT-Net for CI and toy data: widths 8 → 4 → 4, K = 8, hidden 8."""
    base = {"widths": (8, 4, 4), "hidden": 8, "k": 8}
    return GTTNet(GTTNetConfig(**{**base, **overrides}))


@register_builder("gttnet_base")
def gttnet_base(**overrides) -> GTTNet:
    """The paper's GTT-Net: widths J → 16 → 8 → 4 → 4, K = 20, Q = 2 (about 16k parameters for J = 31)."""
    return GTTNet(GTTNetConfig(**overrides))


@register_builder("gttnet_pointnet")
def gttnet_pointnet(**overrides) -> GTTNet:
    """The cross-domain variant: PointNet (10 virtual points) in front of the paper's U-Net."""
    base = {"pointnet": True, "domains": {"cmu31": 31}}
    return GTTNet(GTTNetConfig(**{**base, **overrides}))
