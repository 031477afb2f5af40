"""ContinuousConvUNet: the GTT-Net encoder-decoder of continuous convolutions with skip concatenation."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from gttnet.model.continuous_conv import ContinuousConv
from gttnet.model.norm import PointSetNorm

__all__ = ["ContinuousConvUNet", "UNetOutput"]


@dataclass
class UNetOutput:
    """What the U-Net hands to the affinity head and the losses.

    Args:
        bottleneck: Latent features F^l, shape ``(N, P_L, 3)``.
        bottleneck_slots: Joint-mixed, normalised patch of the bottleneck layer, shape ``(N, K+1, P_L, 3)``;
            None when not asked for (``slots=False``).
        output: Reconstruction of the (normalised) input, shape ``(N, P_0, 3)``; None without the decoder.
        pairs: ``(decoder, encoder)`` feature pairs for ℓ^AE, output/input first, then each hidden level
            (empty without the decoder).
    """

    bottleneck: torch.Tensor
    bottleneck_slots: torch.Tensor | None
    output: torch.Tensor | None
    pairs: list[tuple[torch.Tensor, torch.Tensor]]


class ContinuousConvUNet(nn.Module):
    """U-Net of :class:`ContinuousConv` layers; no pooling, :class:`PointSetNorm` after every hidden layer.

    Encoder widths (pseudo-points) ``in_points → widths[0] → ... → widths[-1]``; the decoder mirrors them,
    each decoder layer reading the previous decoder output concatenated with the mirrored encoder level.
    The last decoder layer reconstructs the input and is not normalised.

    Args:
        in_points: Input pseudo-points P_0 (the joint count J, or PointNet's 10 virtual points).
        widths: Encoder widths after the input, e.g. ``(16, 8, 4, 4)`` (paper: 31 → 16 → 8 → 4 → 4).
        n_slots: Patch size K+1.
        hidden: Hidden width of every weight MLP.
        slot_rank: Feed every slot MLP the neighbour rank (see :class:`ContinuousConv`).
    """

    def __init__(
        self,
        in_points: int,
        widths: tuple[int, ...],
        *,
        n_slots: int,
        hidden: int = 16,
        slot_rank: bool = False,
    ) -> None:
        super().__init__()
        if len(widths) < 1:
            raise ValueError("widths must hold at least one encoder level")
        full = (in_points, *widths)
        self.levels = full
        self.encoders = nn.ModuleList(
            ContinuousConv(full[i], full[i + 1], n_slots=n_slots, hidden=hidden, slot_rank=slot_rank)
            for i in range(len(widths))
        )
        self.enc_norms = nn.ModuleList(PointSetNorm(w) for w in widths)
        depth = len(widths)
        decoders = []
        for i in range(depth - 1, -1, -1):  # decoder producing level i
            n_in = full[i + 1] if i == depth - 1 else 2 * full[i + 1]
            decoders.append(
                ContinuousConv(n_in, full[i], n_slots=n_slots, hidden=hidden, slot_rank=slot_rank)
            )
        self.decoders = nn.ModuleList(decoders)
        self.dec_norms = nn.ModuleList(PointSetNorm(full[i]) for i in range(depth - 1, 0, -1))

    def forward(
        self,
        x: torch.Tensor,
        index: torch.Tensor,
        mask: torch.Tensor,
        seg: torch.Tensor,
        n_seg: int,
        *,
        decode: bool = True,
        slots: bool = True,
    ) -> UNetOutput:
        """Encode and decode a packed batch of sequences.

        Args:
            x: Normalised input point sets, shape ``(N, P_0, 3)``.
            index: Patch slot image indices into the packed batch, shape ``(N, K+1)``.
            mask: Real slots, shape ``(N, K+1)`` bool.
            seg: Sequence id of each image, shape ``(N,)``.
            n_seg: Number of sequences S.
            decode: Run the decoder (its outputs feed only the autoencoding loss ℓ^AE; the affinity reads
                the bottleneck, so inference skips it: half the layers, same affinities).
            slots: Normalise and return the bottleneck's per-slot features (the reference affinity only).

        Returns:
            :class:`UNetOutput`.
        """
        enc = [x]
        patch = x.new_zeros(0)
        for conv, norm in zip(self.encoders, self.enc_norms, strict=True):
            h, patch = conv(enc[-1], index, mask)
            enc.append(norm(h, seg, n_seg))
        bottleneck_slots = None
        if slots:
            n, s = patch.shape[:2]
            slot_seg = seg[:, None].expand(n, s).reshape(-1)
            patch = self.enc_norms[-1](patch.reshape(n * s, *patch.shape[2:]), slot_seg, n_seg)
            bottleneck_slots = patch.reshape(n, s, *patch.shape[1:])
        if not decode:
            return UNetOutput(bottleneck=enc[-1], bottleneck_slots=bottleneck_slots, output=None, pairs=[])
        depth = len(self.encoders)
        pairs: list[tuple[torch.Tensor, torch.Tensor]] = []
        d = enc[-1]
        for j, conv in enumerate(self.decoders):
            level = depth - 1 - j
            inp = d if j == 0 else torch.cat([d, enc[level + 1]], dim=1)
            d, _ = conv(inp, index, mask)
            if level > 0:
                d = self.dec_norms[j](d, seg, n_seg)
            pairs.append((d, enc[level]))
        return UNetOutput(bottleneck=enc[-1], bottleneck_slots=bottleneck_slots, output=d, pairs=pairs[::-1])
