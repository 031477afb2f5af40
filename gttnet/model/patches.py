"""Neighbourhood patches: gather each image's own features and its K neighbours' into one tensor."""

from __future__ import annotations

import torch

__all__ = ["patch_index", "build_patches"]


def patch_index(nbr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Slot indices of every image's patch: slot 0 is the image itself, slots 1..K its neighbours.

    Args:
        nbr: Neighbour image indices, shape ``(N, K)`` int64, ``-1`` where padded.

    Returns:
        ``(index, mask)``: image index of each slot, shape ``(N, K+1)`` (pads point at the image
        itself so gathers stay in range), and which slots are real, shape ``(N, K+1)`` bool.
    """
    if nbr.ndim != 2:
        raise ValueError(f"nbr must have shape (N, K), got {tuple(nbr.shape)}")
    n = nbr.shape[0]
    own = torch.arange(n, device=nbr.device, dtype=torch.long)[:, None]
    nbr = nbr.long()
    mask = torch.cat([torch.ones_like(own, dtype=torch.bool), nbr >= 0], dim=1)
    index = torch.cat([own, torch.where(nbr >= 0, nbr, own)], dim=1)
    return index, mask


def build_patches(x: torch.Tensor, nbr: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Patch tensor of per-image point sets over their neighbourhoods.

    Args:
        x: Per-image point sets (e.g. X_init in world, metres), shape ``(N, J, 3)``.
        nbr: Neighbour image indices, shape ``(N, K)``, ``-1`` where padded.

    Returns:
        ``(patches, mask)``: shape ``(N, K+1, J, 3)`` with slot 0 the image itself (padded slots repeat
        slot 0 and are zeroed), and the slot mask, shape ``(N, K+1)`` bool.

    Example:
        >>> x = torch.arange(12.0).reshape(2, 2, 3)
        >>> p, m = build_patches(x, torch.tensor([[1], [-1]]))
        >>> p.shape, m.tolist()
        (torch.Size([2, 2, 2, 3]), [[True, True], [True, False]])
    """
    if x.ndim != 3 or x.shape[-1] != 3:
        raise ValueError(f"x must have shape (N, J, 3), got {tuple(x.shape)}")
    if nbr.shape[0] != x.shape[0]:
        raise ValueError(f"nbr must have {x.shape[0]} rows, got {nbr.shape[0]}")
    index, mask = patch_index(nbr)
    patches = x[index] * mask[..., None, None].to(x.dtype)
    return patches, mask
