"""PointSetNorm: the GTT-Net layer normalisation of pseudo-point features, per sequence of a packed batch."""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["PointSetNorm", "segment_mean"]


def segment_mean(values: torch.Tensor, seg: torch.Tensor, n_seg: int) -> torch.Tensor:
    """Mean of rows per segment.

    Args:
        values: Per-row values, shape ``(N, ...)``.
        seg: Segment (sequence) id of each row, shape ``(N,)`` int64 in ``[0, n_seg)``.
        n_seg: Number of segments S.

    Returns:
        Per-segment means, shape ``(S, ...)``.
    """
    flat = values.reshape(values.shape[0], -1)
    total = flat.new_zeros((n_seg, flat.shape[1])).index_add_(0, seg, flat)
    count = flat.new_zeros((n_seg,)).index_add_(0, seg, flat.new_ones(flat.shape[0]))
    return (total / count.clamp_min(1.0)[:, None]).reshape((n_seg,) + values.shape[1:])


class PointSetNorm(nn.Module):
    """Layer norm of pseudo-point features: subtract each image's centroid, divide by a per-channel scale.

    The scale of channel ``p`` is the RMS of its centred coordinates over all images of the same sequence
    (so a whole sequence scaled by s gives identical outputs; images inside one sequence keep their
    relative size). Learnable per-channel gain ``gamma`` and per-channel 3-D shift ``beta`` follow.

    Args:
        channels: Number of pseudo-points P.
        eps: Added to the variance, squared units of the input.
    """

    def __init__(self, channels: int, *, eps: float = 1e-6) -> None:
        super().__init__()
        self.gamma = nn.Parameter(torch.ones(channels, 1))
        self.beta = nn.Parameter(torch.zeros(channels, 3))
        self.eps = eps

    def forward(self, x: torch.Tensor, seg: torch.Tensor, n_seg: int) -> torch.Tensor:
        """Normalise.

        Args:
            x: Features, shape ``(N, P, 3)`` (any extra leading dims are folded into N by the caller).
            seg: Sequence id of each image, shape ``(N,)``.
            n_seg: Number of sequences S in the packed batch.

        Returns:
            Normalised features, shape ``(N, P, 3)``.
        """
        xc = x - x.mean(dim=1, keepdim=True)
        var = segment_mean(xc.pow(2).mean(dim=-1), seg, n_seg)  # (S, P)
        scale = torch.sqrt(var[seg] + self.eps)[..., None]
        return xc / scale * self.gamma + self.beta
