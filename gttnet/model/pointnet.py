"""PointNetStream: map a shape of any joint count to a fixed set of virtual 3-D points, with per-domain decoders."""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["PointNetStream"]


def _mlp(sizes: tuple[int, ...], *, last_act: bool) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2 or last_act:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class PointNetStream(nn.Module):
    """PointNet encoder (paper Fig. 2b) and one reconstruction decoder per domain.

    Each image's shape is centred on its barycentre, passed through a shared per-point MLP
    ``3 → 64 → 128 → 512``, max-pooled over points, then ``512 → 128 → 64 → 3·V``; the output is read as
    V virtual 3-D points, and the barycentre is added back so shapes keep their spatial separation.

    Args:
        domains: Joint count of each domain (topology name, e.g. ``{"cmu31": 31}``); one decoder each.
        n_virtual: Virtual points V (paper: 10).
    """

    def __init__(self, domains: dict[str, int], *, n_virtual: int = 10) -> None:
        super().__init__()
        self.n_virtual = n_virtual
        self.point_mlp = _mlp((3, 64, 128, 512), last_act=True)
        self.head = _mlp((512, 128, 64, 3 * n_virtual), last_act=False)
        self.decoders = nn.ModuleDict(
            {name: _mlp((3 * n_virtual, 64, 128, 3 * j), last_act=False) for name, j in domains.items()}
        )
        self.domain_joints = dict(domains)

    def forward(
        self, x: torch.Tensor, visible: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Encode shapes.

        Args:
            x: Shapes in world, metres, shape ``(N, J, 3)``.
            visible: Joints to pool over, shape ``(N, J)`` bool; all when None. Rows with none use all.

        Returns:
            ``(virtual, latent, bary)``: virtual points in world, shape ``(N, V, 3)``; the latent code,
            shape ``(N, 3V)``; the barycentres, shape ``(N, 1, 3)``.
        """
        if x.ndim != 3 or x.shape[-1] != 3:
            raise ValueError(f"x must have shape (N, J, 3), got {tuple(x.shape)}")
        if visible is None:
            visible = torch.ones(x.shape[:2], dtype=torch.bool, device=x.device)
        visible = visible | ~visible.any(dim=1, keepdim=True)
        w = visible.to(x.dtype)[..., None]
        bary = (x * w).sum(1, keepdim=True) / w.sum(1, keepdim=True)
        h = self.point_mlp(x - bary)
        h = h.masked_fill(~visible[..., None], float("-inf")).amax(dim=1)
        latent = self.head(h)
        virtual = latent.reshape(-1, self.n_virtual, 3) + bary
        return virtual, latent, bary

    def decode(self, latent: torch.Tensor, bary: torch.Tensor, domain: str) -> torch.Tensor:
        """Reconstruct a domain's shapes for ℓ^P.

        Args:
            latent: Latent codes, shape ``(N, 3V)``.
            bary: Barycentres, shape ``(N, 1, 3)``.
            domain: Domain (topology) name.

        Returns:
            Reconstructed shapes in world, metres, shape ``(N, J_domain, 3)``.
        """
        if domain not in self.decoders:
            raise KeyError(f"no PointNet decoder for domain {domain!r}; known: {sorted(self.decoders)}")
        return self.decoders[domain](latent).reshape(latent.shape[0], -1, 3) + bary
