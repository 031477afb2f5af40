"""GTT-Net training losses, one function each (ℓ^AE, ℓ^A, ℓ^X, ℓ^S, ℓ^P); weights come from the stage."""

from __future__ import annotations

import torch

from gttnet.model.affinity import AffinityOutput

__all__ = [
    "NORMS",
    "autoencoding_loss",
    "affinity_loss",
    "structure_loss",
    "smoothness_loss",
    "pointnet_loss",
    "pseudo_affinity_targets",
]

#: ``"mse"``: squared Frobenius norm / count (the paper's equations);
#: ``"fro"``: non-squared Frobenius norm / count (the reference code).
NORMS: tuple[str, ...] = ("mse", "fro")


def _reduce(sq_sum: torch.Tensor, count: float, norm: str) -> torch.Tensor:
    if norm == "mse":
        return sq_sum / count
    if norm == "fro":
        return torch.sqrt(sq_sum + 1e-12) / count
    raise ValueError(f"norm must be one of {NORMS}, got {norm!r}")


def autoencoding_loss(pairs: list[tuple[torch.Tensor, torch.Tensor]], *, norm: str = "mse") -> torch.Tensor:
    """ℓ^AE: U-Net output vs its input, plus each decoder level vs its mirrored encoder level.

    Args:
        pairs: ``(decoded, encoded)`` pseudo-point sets, each shape ``(N, P_i, 3)`` (normalised units).
        norm: One of :data:`NORMS`; each pair is divided by ``N·P_i``.

    Returns:
        Scalar loss.
    """
    total = pairs[0][0].new_zeros(())
    for dec, enc in pairs:
        total = total + _reduce((dec - enc).pow(2).sum(), dec.shape[0] * dec.shape[1], norm)
    return total


def pseudo_affinity_targets(mask: torch.Tensor, *, q: int = 2) -> torch.Tensor:
    """Self-supervised A^G over the neighbourhood: 1 on each image's first Q real neighbour slots.

    Neighbourhoods are ranked by pseudo-triangulation cost (or by time under full sequencing), so
    the labels use only the observations.

    Args:
        mask: Real neighbour slots, shape ``(N, K)`` bool.
        q: Slots labelled 1 per row.

    Returns:
        Targets, shape ``(N, K)``.
    """
    rank = torch.cumsum(mask.long(), dim=1)
    return ((rank <= q) & mask).float()


def affinity_loss(aff: AffinityOutput, target: torch.Tensor, *, norm: str = "mse") -> torch.Tensor:
    """ℓ^A: ``A^D - A^G`` over each image's neighbourhood, plus the same on the kept top-Q entries.

    Args:
        aff: Network affinities (values over the neighbourhood and kept entries).
        target: A^G gathered over the neighbourhood, shape ``(N, K)`` (binary, continuous or pseudo).
        norm: One of :data:`NORMS`; both terms are divided by N (per-row sums, as in the paper).

    Returns:
        Scalar loss.
    """
    if target.shape != aff.values.shape:
        raise ValueError(f"target must have shape {tuple(aff.values.shape)}, got {tuple(target.shape)}")
    target = target.to(aff.values.dtype)
    n = aff.values.shape[0]
    m = aff.mask.to(aff.values.dtype)
    whole = _reduce(((aff.values - target) * m).pow(2).sum(), n, norm)
    kept_t = target.gather(1, aff.keep)
    kept_m = aff.mask.gather(1, aff.keep).to(aff.values.dtype)
    kept = _reduce(((aff.kept - kept_t) * kept_m).pow(2).sum(), n, norm)
    return whole + kept


def structure_loss(x_est: torch.Tensor, x_gt: torch.Tensor, *, norm: str = "mse") -> torch.Tensor:
    """ℓ^X: ``||X^E - X^G|| / (N·P)`` over all joints, missing ones included.

    Args:
        x_est: DLOE-layer structure in world, metres, shape ``(N, J, 3)``.
        x_gt: Ground truth in world, metres, shape ``(N, J, 3)``.
        norm: One of :data:`NORMS`.

    Returns:
        Scalar loss (m² for ``mse``).
    """
    if x_est.shape != x_gt.shape:
        raise ValueError(f"x_est {tuple(x_est.shape)} and x_gt {tuple(x_gt.shape)} differ in shape")
    return _reduce((x_est - x_gt.to(x_est.dtype)).pow(2).sum(), x_est.shape[0] * x_est.shape[1], norm)


def smoothness_loss(a_sparse: torch.Tensor, x: torch.Tensor, *, lambda1: float = 0.1) -> torch.Tensor:
    """ℓ^S: the first two DLOE terms, ``Σ_c ||L_out x_c||² + λ1 Σ_c x_cᵀ L_sym x_c``, divided by N·P.

    L is built from the row-normalised A^S (rows sum to 1 where they have any weight), so the loss
    cannot be lowered by shrinking every affinity towards zero. Needs no ground truth.

    Args:
        a_sparse: A^S, shape ``(N, N)``.
        x: Structure the affinity should explain (X^E), world, metres, shape ``(N, J, 3)``.
        lambda1: Weight of the compactness term.

    Returns:
        Scalar loss, m².
    """
    n, j = x.shape[:2]
    W = a_sparse / a_sparse.sum(dim=1, keepdim=True).clamp_min(1e-12)
    flat = x.reshape(n, -1).to(W.dtype)
    smooth = (flat - W @ flat).pow(2).sum()
    S = W + W.T
    lap = S.sum(dim=1, keepdim=True) * flat - S @ flat
    compact = (flat * lap).sum()
    return (smooth + lambda1 * compact) / (n * j)


def pointnet_loss(recon: torch.Tensor, x_init: torch.Tensor, *, norm: str = "mse") -> torch.Tensor:
    """ℓ^P: PointNet domain-decoder reconstruction vs X_init, divided by N·P.

    Args:
        recon: Decoded shapes in world, metres, shape ``(N, J, 3)``.
        x_init: PointNet input (X_init) in world, metres, shape ``(N, J, 3)``.
        norm: One of :data:`NORMS`.

    Returns:
        Scalar loss.
    """
    if recon.shape != x_init.shape:
        raise ValueError(f"recon {tuple(recon.shape)} and x_init {tuple(x_init.shape)} differ in shape")
    return _reduce((recon - x_init).pow(2).sum(), recon.shape[0] * recon.shape[1], norm)
