"""Assembly and solution of the per-joint X-step linear systems, dense (torch) or sparse (SciPy)."""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass

import numpy as np
import torch
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import splu

from gttnet.errors import GttNetError

__all__ = ["SingularStructureError", "StructureSystem", "build_system", "solve_dense", "solve_sparse"]

log = logging.getLogger(__name__)


class SingularStructureError(GttNetError):
    """The X-step has no unique solution (a joint unobserved in a connected part of the graph)."""


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


def build_system(C, r, vis, *, lambda2, x_prior, eps) -> StructureSystem:
    """Pinned (``lambda2=None``: depth along the ray, 3 free coordinates when missing) or full-3N systems.

    Args:
        C: Centres, shape ``(B, N, 3)``. r: rays ``(B, N, J, 3)``. vis: mask ``(B, N, J)``.
        lambda2: Ray weight or None. x_prior: ``(B, N, J, 3)`` or None. eps: ridge ``(B,)`` or None.
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
        W = lambda2 * P
        w = lambda2 * (P @ CS.unsqueeze(-1)).squeeze(-1)
    V = V * active.unsqueeze(-1)
    if x_prior is not None:
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
        q = q - (sys.W @ sys.Ct.unsqueeze(-1)).squeeze(-1) + sys.w
    return q


def _block_diag_term(V0, VE, nE, W, n):
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


def solve_dense(M: torch.Tensor, sys: StructureSystem) -> torch.Tensor:
    """Batched dense Cholesky over the active unknowns of every system; autograd-friendly.

    Unknowns are ordered as every image's slot 0 (its depth, or x when missing) in image order, then
    the extra slots of the system, padded to the largest count. The slot-0 block is then a plain
    elementwise product with M (no gather), which keeps assembly cheap next to the factorisation.

    Args:
        M: Laplacian part, shape ``(B, N, N)``.
        sys: The systems.

    Returns:
        X, shape ``(B, N, J, 3)``.
    """
    s, n, _ = sys.active.shape
    b, j = sys.batch, sys.joints
    extra = sys.active[:, :, 1:].reshape(s, 2 * n)
    count = extra.sum(1)
    emax = int(count.max()) if s else 0
    order = torch.argsort((~extra).to(torch.int8), dim=1, stable=True)[:, :emax]
    pad = torch.arange(emax, device=M.device).unsqueeze(0) >= count.unsqueeze(1)
    nE, sE = order // 2, order % 2 + 1
    ar = torch.arange(s, device=M.device)[:, None]
    V0 = sys.V[:, :, 0]
    VE = sys.V[ar, nE, sE]  # (S, E, 3), zero on pads (inactive slots)
    M4 = M.unsqueeze(1).expand(b, j, n, n)
    H00 = (M4 * (V0 @ V0.transpose(-1, -2)).view(b, j, n, n)).reshape(s, n, n)
    ME = M4.gather(-1, nE.view(b, j, 1, emax).expand(b, j, n, emax)).reshape(s, n, emax)
    H0E = ME * (V0 @ VE.transpose(-1, -2))
    HEE = ME.gather(1, nE.unsqueeze(-1).expand(s, emax, emax)) * (VE @ VE.transpose(-1, -2))
    if sys.W is not None:
        d00, d0E, dEE = _block_diag_term(V0, VE, nE, sys.W, n)
        H00 = H00 + torch.diag_embed(d00)
        H0E = H0E + d0E
        HEE = HEE + dEE
    HEE = HEE + torch.diag_embed(pad.to(M.dtype))
    H = torch.cat([torch.cat([H00, H0E], -1), torch.cat([H0E.transpose(-1, -2), HEE], -1)], -2)
    q = _linear_term(M, sys)
    rhs = torch.cat([(V0 * q).sum(-1), (VE * q[ar, nE]).sum(-1)], -1).unsqueeze(-1)
    L, info = torch.linalg.cholesky_ex(H)
    if bool((info != 0).any()):
        warnings.warn(
            "X-step system not numerically positive definite (ill-conditioned lambda2 or dtype); using LU",
            RuntimeWarning,
            stacklevel=3,
        )
        z = torch.linalg.solve(H, rhs)
    else:
        z = torch.cholesky_solve(rhs, L)
    z = z.squeeze(-1)
    # Pads map to inactive slots (zero direction), so scattering their zero values is harmless.
    zE = torch.zeros(s, 2 * n, dtype=z.dtype, device=z.device).scatter(1, order, z[:, n:])
    zf = torch.cat([z[:, :n].unsqueeze(-1), zE.view(s, n, 2)], -1)
    return sys.to_points(zf)


def _assemble(Mb: np.ndarray, nz, V: np.ndarray, active: np.ndarray, W: np.ndarray | None):
    """Sparse matrix of one system from its image slots (float64 NumPy); returns (H, pos)."""
    n = V.shape[0]
    pos = np.full((n, 3), -1, dtype=np.int64)
    pos[active] = np.arange(int(active.sum()))
    ri, ci, vals = nz
    VV = np.einsum("ksd,ktd->kst", V[ri], V[ci])
    rows = np.broadcast_to(pos[ri][:, :, None], VV.shape)
    cols = np.broadcast_to(pos[ci][:, None, :], VV.shape)
    data = [(vals[:, None, None] * VV).ravel()]
    rr, cc = [rows.ravel()], [cols.ravel()]
    if W is not None:
        D = np.einsum("nsd,nde,nte->nst", V, W, V)
        data.append(D.ravel())
        rr.append(np.broadcast_to(pos[:, :, None], D.shape).ravel())
        cc.append(np.broadcast_to(pos[:, None, :], D.shape).ravel())
    data, rr, cc = np.concatenate(data), np.concatenate(rr), np.concatenate(cc)
    keep = (rr >= 0) & (cc >= 0)
    size = int(active.sum())
    return csc_matrix((data[keep], (rr[keep], cc[keep])), shape=(size, size)), pos


class _SparseSolve(torch.autograd.Function):
    """X = solve(M); backward: adjoint solve with the same factors, dL/dM = -sum_joints G X^T."""

    @staticmethod
    def forward(ctx, M: torch.Tensor, sys: StructureSystem) -> torch.Tensor:  # noqa: D102
        s, n, _ = sys.active.shape
        Mn = M.detach().cpu().double().numpy()
        V = sys.V.detach().cpu().double().numpy()
        act = sys.active.cpu().numpy()
        q = _linear_term(M.detach(), sys).cpu().double().numpy()
        W = None if sys.W is None else sys.W.detach().cpu().double().numpy()
        nzs = []
        for b in range(Mn.shape[0]):
            ri, ci = np.nonzero(Mn[b])
            nzs.append((ri, ci, Mn[b][ri, ci]))
        zs = np.zeros((s, n, 3))
        factors = []
        for k in range(s):
            H, pos = _assemble(
                Mn[k // sys.joints], nzs[k // sys.joints], V[k], act[k], None if W is None else W[k]
            )
            rhs = np.einsum("nsd,nd->ns", V[k], q[k])[act[k]]
            try:
                lu = splu(H, permc_spec="MMD_AT_PLUS_A")
            except RuntimeError as exc:
                raise SingularStructureError(f"X-step system {k} is singular: {exc}") from exc
            zs[k][act[k]] = lu.solve(rhs)
            factors.append((lu, pos))
        z = torch.as_tensor(zs, dtype=M.dtype, device=M.device)
        X = sys.to_points(z)
        ctx.factors, ctx.sys = factors, sys
        ctx.save_for_backward(X)
        return X

    @staticmethod
    def backward(ctx, grad_X: torch.Tensor):  # noqa: D102
        (X,) = ctx.saved_tensors
        sys = ctx.sys
        s, n, _ = sys.active.shape
        V = sys.V.detach().cpu().double().numpy()
        gX = grad_X.transpose(1, 2).reshape(s, n, 3).detach().cpu().double().numpy()
        Xs = X.transpose(1, 2).reshape(s, n, 3).detach().cpu().double().numpy()
        grad_M = np.zeros((sys.batch, n, n))
        for k, (lu, pos) in enumerate(ctx.factors):
            act = pos >= 0
            g = np.einsum("nsd,nd->ns", V[k], gX[k])[act]
            lam = np.zeros((n, 3))
            lam[act] = lu.solve(g, trans="T")
            G = np.einsum("ns,nsd->nd", lam, V[k])
            grad_M[k // sys.joints] -= G @ Xs[k].T
        return torch.as_tensor(grad_M, dtype=grad_X.dtype, device=grad_X.device), None


def solve_sparse(M: torch.Tensor, sys: StructureSystem) -> torch.Tensor:
    """Per-system sparse LU (SuperLU, float64, CPU), differentiable w.r.t. M only.

    Args:
        M: Laplacian part, shape ``(B, N, N)``.
        sys: The systems.

    Returns:
        X, shape ``(B, N, J, 3)``, M's dtype and device.
    """
    return _SparseSolve.apply(M, sys)
