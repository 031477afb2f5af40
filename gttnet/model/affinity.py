"""AffinityHead: decode pairwise affinities A^D from latent features and sparsify them to A^S."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

__all__ = ["AFFINITY_MODES", "AffinityHead", "AffinityOutput", "sparse_affinity"]

#: ``paper``: image n's own embedding vs image m's own embedding (symmetric);
#: ``reference``: slot 0 vs slot k inside image n's own patch (the authors' code).
AFFINITY_MODES: tuple[str, ...] = ("paper", "reference")


@dataclass
class AffinityOutput:
    """Affinities over each image's neighbourhood and the kept top-Q entries.

    Args:
        values: A^D over the neighbourhood, shape ``(N, K)``, in (0, 1]; 0 at padded slots.
        mask: Real neighbour slots, shape ``(N, K)`` bool.
        keep: Neighbour slot (0..K-1) of each kept entry, shape ``(N, Q)`` int64.
        kept: Kept values (differentiable), shape ``(N, Q)``; 0 where the row had fewer than Q neighbours.
    """

    values: torch.Tensor
    mask: torch.Tensor
    keep: torch.Tensor
    kept: torch.Tensor


class AffinityHead(nn.Module):
    """``A^D_nm = 2 / (1 + exp ||F_n - F_m||)`` on bottleneck features, then top-Q per row.

    The paper's ``1/(1+exp d)`` peaks at 0.5; the reference code rescales by the global maximum. We scale by
    the fixed factor 2 instead, so identical features give 1 (matching binary A^G) and the head stays a pure
    function of each pair. No parameters: the U-Net learns the embedding.

    Args:
        mode: One of :data:`AFFINITY_MODES`.
        top_q: Entries kept per row (Q; paper: 2).
        eps: Added under the square root of the distance, keeps the gradient finite at zero distance.
    """

    def __init__(self, mode: str = "paper", *, top_q: int = 2, eps: float = 1e-9) -> None:
        super().__init__()
        if mode not in AFFINITY_MODES:
            raise ValueError(f"affinity mode must be one of {AFFINITY_MODES}, got {mode!r}")
        if top_q < 1:
            raise ValueError(f"top_q must be >= 1, got {top_q}")
        self.mode, self.top_q, self.eps = mode, top_q, eps

    def forward(
        self,
        feats: torch.Tensor,
        slot_feats: torch.Tensor | None,
        index: torch.Tensor,
        mask: torch.Tensor,
        *,
        top_q: int | None = None,
    ) -> AffinityOutput:
        """Affinities over the neighbourhood.

        Args:
            feats: Bottleneck features per image, shape ``(N, P, 3)``.
            slot_feats: Bottleneck features of each patch slot, shape ``(N, K+1, P, 3)`` (reference mode;
                may be None in paper mode).
            index: Patch slot image indices (slot 0 = self), shape ``(N, K+1)``.
            mask: Real slots, shape ``(N, K+1)`` bool.
            top_q: Entries kept per row for this call; None = ``self.top_q``.

        Returns:
            :class:`AffinityOutput`.
        """
        if self.mode == "paper":
            f = feats.flatten(1)
            diff = f[index[:, 1:]] - f[:, None]
        else:
            if slot_feats is None:
                raise ValueError("the reference affinity needs the bottleneck's slot features")
            f = slot_feats.flatten(2)
            diff = f[:, 1:] - f[:, :1]
        dist = torch.sqrt(diff.pow(2).sum(-1) + self.eps)
        nmask = mask[:, 1:]
        values = 2.0 * torch.sigmoid(-dist) * nmask.to(dist.dtype)
        q = min(self.top_q if top_q is None else int(top_q), values.shape[1])
        ranked = values.masked_fill(~nmask, -1.0)
        _, keep = torch.topk(ranked, q, dim=1)
        kept = values.gather(1, keep)
        return AffinityOutput(values=values, mask=nmask, keep=keep, kept=kept)


def sparse_affinity(
    kept: torch.Tensor, keep: torch.Tensor, nbr: torch.Tensor, *, chain: torch.Tensor | None = None
) -> torch.Tensor:
    """Dense sparse-pattern A^S of one sequence from its kept entries (differentiable w.r.t. ``kept``).

    Args:
        kept: Kept affinity values, shape ``(N, Q)``.
        keep: Neighbour slot of each kept value, shape ``(N, Q)``.
        nbr: Neighbour image indices local to the sequence, shape ``(N, K)``, ``-1`` padded.
        chain: Within-stream chain (partial sequencing), shape ``(N, N)`` 0/1, or None. Row n is added
            scaled by row n's second kept value (its first when Q = 1), identically at train and test time.

    Returns:
        A^S, shape ``(N, N)``, zero diagonal.
    """
    n = kept.shape[0]
    cols = nbr.long().gather(1, keep)
    rows = torch.arange(n, device=kept.device)[:, None].expand_as(cols)
    valid = cols >= 0
    cols = torch.where(valid, cols, rows)
    vals = kept * valid.to(kept.dtype)
    A = kept.new_zeros((n, n)).index_put(
        (rows.reshape(-1), cols.reshape(-1)), vals.reshape(-1), accumulate=True
    )
    if chain is not None:
        scale = kept[:, min(1, kept.shape[1] - 1)]
        A = A + scale[:, None] * chain.to(kept.dtype)
    return A * (1.0 - torch.eye(n, dtype=kept.dtype, device=kept.device))
