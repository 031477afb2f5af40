"""The per-joint X-step linear systems: their slot parameterisation and the dense batched torch solve."""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass
from typing import Any

import torch

from gttnet.errors import SingularStructureError

__all__ = ["SingularStructureError", "StructureSystem", "build_system", "solve_dense"]

log = logging.getLogger(__name__)


@dataclass
class StructureSystem:
    """The X-step of S = B J independent systems (one per batch item and joint) over N images.

    Image n of system s contributes up to three unknowns z (its "slots"); its point is
    ``X_n = Ct_n + sum_slot z_slot V_n[slot]``. With M the Laplacian part, the energy is
    ``sum_c x_c^T M x_c + sum_n X_n^T W_n X_n - 2 w_n . X_n``.

    Args:
        V: Slot directions, shape ``(S, N, 3, 3)`` (slot, xyz).
        active: Which slots are unknowns, shape ``(S, N, 3)`` bool.
        Ct: Fixed offset of each point, metres, shape ``(S, N, 3)``.
        W: Per-image quadratic weight, shape ``(S, N, 3, 3)``, or None.
        w: Per-image linear weight, shape ``(S, N, 3)``, or None.
        batch: Batch size B (system s belongs to batch item ``s // J``).
        joints: Joints J.
    """

    V: torch.Tensor
    active: torch.Tensor
    Ct: torch.Tensor
    W: torch.Tensor | None
    w: torch.Tensor | None
    batch: int
    joints: int

    def to_points(self, z_slots: torch.Tensor) -> torch.Tensor:
        """Points from slot values ``(S, N, 3)`` (zero where inactive), as ``(B, N, J, 3)``."""
        X = self.Ct + (z_slots.unsqueeze(-1) * self.V).sum(-2)
        s, n, _ = X.shape
        return X.reshape(self.batch, self.joints, n, 3).transpose(1, 2)


def _per_image(lambda2: float | torch.Tensor, b: int, j: int, n: int, like: torch.Tensor) -> torch.Tensor:
    """A ray weight given once, per image ``(N,)`` or per batch item and image ``(B, N)``, as ``(B J, N)``."""
    lam = torch.as_tensor(lambda2, dtype=like.dtype, device=like.device)
    if lam.ndim == 0:
        return lam.expand(b * j, n)
    if lam.shape not in ((n,), (b, n)):
        raise ValueError(
            f"lambda2 must be a number or have shape ({n},) or ({b}, {n}), got {tuple(lam.shape)}"
        )
    return lam.expand(b, n).unsqueeze(1).expand(b, j, n).reshape(b * j, n)


def build_system(
    C: torch.Tensor,
    r: torch.Tensor,
    vis: torch.Tensor,
    *,
    lambda2: float | torch.Tensor | None,
    x_prior: torch.Tensor | None,
    eps: torch.Tensor | None,
) -> StructureSystem:
    """Pinned (``lambda2=None``: depth along the ray, 3 free coordinates when missing) or full-3N systems.

    Args:
        C: Camera centres, shape ``(B, N, 3)``.
        r: Unit rays, shape ``(B, N, J, 3)``.
        vis: Visibility mask, shape ``(B, N, J)``.
        lambda2: Ray weight (a number, or per image: shape ``(N,)`` or ``(B, N)``), or None for the pinned
            system.
        x_prior: Prior points, shape ``(B, N, J, 3)``, or None.
        eps: Ridge per batch item, shape ``(B,)``, or None.

    Returns:
        The assembled :class:`StructureSystem`.
    """
    b, n, j, _ = r.shape
    s = b * j
    rS = r.permute(0, 2, 1, 3).reshape(s, n, 3)
    vS = vis.permute(0, 2, 1).reshape(s, n)
    CS = C.unsqueeze(1).expand(b, j, n, 3).reshape(s, n, 3)
    eye = torch.eye(3, dtype=r.dtype, device=r.device)
    V = eye.expand(s, n, 3, 3)
    zero = torch.zeros((), dtype=r.dtype, device=r.device)
    if lambda2 is None:
        active = torch.stack([torch.ones_like(vS), ~vS, ~vS], -1)
        V = torch.cat([torch.where(vS.unsqueeze(-1), rS, eye[0]).unsqueeze(-2), V[:, :, 1:]], -2)
        Ct = torch.where(vS.unsqueeze(-1), CS, zero)
        W = w = None
    else:
        active = torch.ones(s, n, 3, dtype=torch.bool, device=r.device)
        Ct = torch.zeros_like(CS)
        P = (eye - rS.unsqueeze(-1) * rS.unsqueeze(-2)) * vS[..., None, None]
        lam = _per_image(lambda2, b, j, n, r)
        W = lam[..., None, None] * P
        w = lam[..., None] * (P @ CS.unsqueeze(-1)).squeeze(-1)
    V = V * active.unsqueeze(-1)
    if x_prior is not None:
        if eps is None:
            raise ValueError("x_prior needs its ridge weight eps, shape (B,)")
        e = eps.repeat_interleave(j).view(s, 1, 1)
        xp = x_prior.permute(0, 2, 1, 3).reshape(s, n, 3)
        ridge = (e.unsqueeze(-1) * eye).expand(s, n, 3, 3)
        W = ridge if W is None else W + ridge
        w = e * xp if w is None else w + e * xp
    return StructureSystem(V=V, active=active, Ct=Ct, W=W, w=w, batch=b, joints=j)


def _linear_term(M: torch.Tensor, sys: StructureSystem) -> torch.Tensor:
    """``q = -(M Ct) - W Ct + w``, per image, shape ``(S, N, 3)``; the right-hand side is ``V . q``."""
    n = M.shape[-1]
    Ct4 = sys.Ct.reshape(sys.batch, sys.joints, n, 3)
    q = -(M.unsqueeze(1) @ Ct4).reshape(-1, n, 3)
    if sys.W is not None:
        assert sys.w is not None  # the ray-weighted system always carries both
        q = q - (sys.W @ sys.Ct.unsqueeze(-1)).squeeze(-1) + sys.w
    return q


def _block_diag_term(
    V0: torch.Tensor, VE: torch.Tensor, nE: torch.Tensor, W: torch.Tensor, n: int
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per-image ``v_a^T W_n v_b`` blocks split as (slot-0 diagonal, slot-0 x extra, extra x extra)."""
    s = V0.shape[0]
    ar = torch.arange(s, device=V0.device)[:, None]
    WV0 = (W @ V0.unsqueeze(-1)).squeeze(-1)  # (S, N, 3)
    d00 = (V0 * WV0).sum(-1)
    d0E_val = (WV0[ar, nE] * VE).sum(-1)  # (S, E): pairs (image nE_e slot 0, extra e)
    d0E = torch.zeros(s, n, VE.shape[1], dtype=V0.dtype, device=V0.device).scatter(
        1, nE.unsqueeze(1), d0E_val.unsqueeze(1)
    )
    WVE = (W[ar, nE] @ VE.unsqueeze(-1)).squeeze(-1)
    dEE = (VE @ WVE.transpose(-1, -2)) * (nE.unsqueeze(-1) == nE.unsqueeze(-2))
    return d00, d0E, dEE


@dataclass
class _Layout:
    """Unknown ordering of the dense path: slot 0 of every image, then each system's extra slots."""

    order: torch.Tensor  # (S, E) flat index (image * 2 + slot - 1) of each extra unknown
    pad: torch.Tensor  # (S, E) padding unknowns
    nE: torch.Tensor  # (S, E) image of each extra unknown
    V0: torch.Tensor  # (S, N, 3) slot-0 directions
    VE: torch.Tensor  # (S, E, 3) extra directions (zero on pads)


def _layout(sys: StructureSystem) -> _Layout:
    s, n, _ = sys.active.shape
    extra = sys.active[:, :, 1:].reshape(s, 2 * n)
    count = extra.sum(1)
    emax = int(count.max()) if s else 0
    order = torch.argsort((~extra).to(torch.int8), dim=1, stable=True)[:, :emax]
    pad = torch.arange(emax, device=extra.device).unsqueeze(0) >= count.unsqueeze(1)
    nE, sE = order // 2, order % 2 + 1
    ar = torch.arange(s, device=extra.device)[:, None]
    return _Layout(order=order, pad=pad, nE=nE, V0=sys.V[:, :, 0], VE=sys.V[ar, nE, sE])


def _assemble_dense(M: torch.Tensor, sys: StructureSystem, lay: _Layout) -> tuple[torch.Tensor, torch.Tensor]:
    """H ``(S, N + E, N + E)`` and rhs ``(S, N + E, 1)``; the slot-0 block is M times ray dot products."""
    s, n, _ = sys.active.shape
    b, j = sys.batch, sys.joints
    emax = lay.nE.shape[1]
    V0, VE, nE = lay.V0, lay.VE, lay.nE
    M4 = M.unsqueeze(1).expand(b, j, n, n)
    ME = M4.gather(-1, nE.view(b, j, 1, emax).expand(b, j, n, emax)).reshape(s, n, emax)
    H0E = ME * (V0 @ VE.transpose(-1, -2))
    HEE = ME.gather(1, nE.unsqueeze(-1).expand(s, emax, emax)) * (VE @ VE.transpose(-1, -2))
    d00 = None
    if sys.W is not None:
        d00, d0E, dEE = _block_diag_term(V0, VE, nE, sys.W, n)
        H0E = H0E + d0E
        HEE = HEE + dEE
    HEE = HEE + torch.diag_embed(lay.pad.to(M.dtype))
    if torch.is_grad_enabled():
        H00 = (M4 * (V0 @ V0.transpose(-1, -2)).view(b, j, n, n)).reshape(s, n, n)
        H00 = H00 if d00 is None else H00 + torch.diag_embed(d00)
        H = torch.cat([torch.cat([H00, H0E], -1), torch.cat([H0E.transpose(-1, -2), HEE], -1)], -2)
    else:  # write the big slot-0 block in place: one memory pass fewer than torch.cat (CPU-bound at N > 300)
        H = M.new_empty(s, n + emax, n + emax)
        torch.mul(M4, (V0 @ V0.transpose(-1, -2)).view(b, j, n, n), out=H[:, :n, :n].view(b, j, n, n))
        if d00 is not None:
            H[:, :n, :n].diagonal(dim1=-2, dim2=-1).add_(d00)
        H[:, :n, n:] = H0E
        H[:, n:, :n] = H0E.transpose(-1, -2)
        H[:, n:, n:] = HEE
    q = _linear_term(M, sys)
    ar = torch.arange(s, device=M.device)[:, None]
    rhs = torch.cat([(V0 * q).sum(-1), (VE * q[ar, nE]).sum(-1)], -1).unsqueeze(-1)
    return H, rhs


def _factor(H: torch.Tensor) -> tuple[str, tuple[torch.Tensor, ...]]:
    L, info = torch.linalg.cholesky_ex(H)
    if not bool((info != 0).any()):
        return "chol", (L,)
    warnings.warn(
        "X-step system not numerically positive definite (ill-conditioned lambda2 or dtype); using LU",
        RuntimeWarning,
        stacklevel=4,
    )
    LU, pivots, info = torch.linalg.lu_factor_ex(H)
    bad = torch.nonzero(info != 0).flatten()
    if bad.numel():
        raise SingularStructureError(
            f"X-step system singular for {bad.numel()} of {H.shape[0]} joint systems (first: system "
            f"{int(bad[0])}, zero pivot {int(info[bad[0]])}): the affinity graph does not pin those joints down"
        )
    return "lu", (LU, pivots)


def _solve_factored(kind: str, fac: tuple[torch.Tensor, ...], rhs: torch.Tensor) -> torch.Tensor:
    return torch.cholesky_solve(rhs, fac[0]) if kind == "chol" else torch.linalg.lu_solve(*fac, rhs)


def _to_points(z: torch.Tensor, sys: StructureSystem, lay: _Layout) -> torch.Tensor:
    s, n, _ = sys.active.shape
    z = z.squeeze(-1)
    # Pads map to inactive slots (zero direction), so scattering their zero values is harmless.
    zE = torch.zeros(s, 2 * n, dtype=z.dtype, device=z.device).scatter(1, lay.order, z[:, n:])
    return sys.to_points(torch.cat([z[:, :n].unsqueeze(-1), zE.view(s, n, 2)], -1))


class _DenseSolve(torch.autograd.Function):
    """X(M) with an adjoint backward: one extra triangular solve instead of differentiating the factorisation.

    With H z = rhs, ``lam = H^-1 dL/dz`` (H symmetric) and ``dL/dM = -sum_joints G X^T`` where
    ``G_n = sum_slots lam v`` (see ``_sparse``); the ray terms do not depend on M.
    """

    @staticmethod
    def forward(ctx: Any, M: torch.Tensor, sys: StructureSystem) -> torch.Tensor:  # noqa: D102
        lay = _layout(sys)
        H, rhs = _assemble_dense(M, sys, lay)
        kind, fac = _factor(H)
        X = _to_points(_solve_factored(kind, fac, rhs), sys, lay)
        ctx.kind, ctx.fac, ctx.lay, ctx.sys = kind, fac, lay, sys
        ctx.save_for_backward(X)
        return X

    @staticmethod
    def backward(ctx: Any, grad_X: torch.Tensor) -> tuple[torch.Tensor, None]:  # noqa: D102
        (X,) = ctx.saved_tensors
        lay, sys = ctx.lay, ctx.sys
        s, n, _ = sys.active.shape
        b, j = sys.batch, sys.joints
        gX = grad_X.transpose(1, 2).reshape(s, n, 3)
        ar = torch.arange(s, device=X.device)[:, None]
        g = torch.cat([(lay.V0 * gX).sum(-1), (lay.VE * gX[ar, lay.nE]).sum(-1)], -1).unsqueeze(-1)
        lam = _solve_factored(ctx.kind, ctx.fac, g).squeeze(-1)
        G = lam[:, :n, None] * lay.V0
        G = G.index_put((ar.expand_as(lay.nE), lay.nE), lam[:, n:, None] * lay.VE, accumulate=True)
        Gf = G.view(b, j, n, 3).transpose(1, 2).reshape(b, n, 3 * j)
        Xf = X.reshape(b, n, 3 * j)
        return -(Gf @ Xf.transpose(-1, -2)), None


def solve_dense(M: torch.Tensor, sys: StructureSystem) -> torch.Tensor:
    """Batched dense Cholesky over the active unknowns of every system.

    Unknowns are ordered as every image's slot 0 (its depth, or x when missing) in image order, then
    the extra slots of the system, padded to the largest count. The slot-0 block is then a plain
    elementwise product with M (no gather), which keeps assembly cheap next to the factorisation.
    Gradients w.r.t. M use an adjoint solve with the saved factor; if the rays or centres need
    gradients, plain autograd through the factorisation is used instead.

    Args:
        M: Laplacian part, shape ``(B, N, N)``.
        sys: The systems.

    Returns:
        X, shape ``(B, N, J, 3)``.
    """
    geometry_grad = torch.is_grad_enabled() and any(
        t is not None and t.requires_grad for t in (sys.V, sys.Ct, sys.W, sys.w)
    )
    if not geometry_grad:
        X: torch.Tensor = _DenseSolve.apply(M, sys)  # type: ignore[no-untyped-call]  # torch leaves it untyped
        return X
    lay = _layout(sys)
    H, rhs = _assemble_dense(M, sys, lay)
    kind, fac = _factor(H)
    return _to_points(_solve_factored(kind, fac, rhs), sys, lay)
