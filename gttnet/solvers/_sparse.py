"""Sparse CPU path of the X-step: SuperLU on the block-diagonal system of all joints, with a custom backward."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import torch

from gttnet.solvers._system import StructureSystem
from gttnet.solvers.numpy_xstep import _assemble, _image_order, _laplacians_np, solve_item  # noqa: F401

__all__ = ["solve_sparse"]

log = logging.getLogger(__name__)


class _SparseSolve(torch.autograd.Function):
    """X(A): forward assembles and factorises once per batch item; backward is one adjoint solve.

    With H z = rhs and adjoint ``lam = H^-T dL/dz``, the gradient w.r.t. the Laplacian part is
    ``dL/dM = -sum_joints G X^T`` with ``G_n = sum_slots lam v`` (a rank-3J matrix), then chained through
    ``M = L^T L + lambda1 L_sym`` and the Laplacian definitions to A.
    """

    @staticmethod
    def forward(ctx: Any, A: torch.Tensor, lambda1: float, sys: StructureSystem) -> torch.Tensor:  # noqa: D102
        b, n, j = sys.batch, A.shape[-1], sys.joints
        An = A.detach().cpu().double().numpy()
        V = sys.V.detach().cpu().double().numpy().reshape(b, j, n, 3, 3)
        act = sys.active.cpu().numpy().reshape(b, j, n, 3)
        Ct = sys.Ct.detach().cpu().double().numpy().reshape(b, j, n, 3)
        W = None if sys.W is None else sys.W.detach().cpu().double().numpy().reshape(b, j, n, 3, 3)
        w = None if sys.w is None else sys.w.detach().cpu().double().numpy().reshape(b, j, n, 3)
        zs = np.zeros((b, j, n, 3))
        saved = []
        for k in range(b):
            z, lu, L, idx = solve_item(
                An[k], lambda1, V[k], act[k], Ct[k], None if W is None else W[k], None if w is None else w[k],
                item=k,
            )  # fmt: skip
            zs[k] = z
            saved.append((lu, L, idx))
        X = sys.to_points(torch.as_tensor(zs.reshape(b * j, n, 3), dtype=A.dtype, device=A.device))
        ctx.saved, ctx.sys, ctx.lambda1 = saved, sys, lambda1
        ctx.save_for_backward(X)
        return X

    @staticmethod
    def backward(ctx: Any, grad_X: torch.Tensor) -> tuple[torch.Tensor, None, None]:  # noqa: D102
        (X,) = ctx.saved_tensors
        sys = ctx.sys
        b, n, j = sys.batch, X.shape[1], sys.joints
        V = sys.V.detach().cpu().double().numpy().reshape(b, j, n, 3, 3)
        act = sys.active.cpu().numpy().reshape(b, j, n, 3)
        gX = grad_X.detach().cpu().double().numpy()  # (B, N, J, 3)
        Xn = X.detach().cpu().double().numpy()
        grad_A = np.zeros((b, n, n))
        for k, (lu, L, idx) in enumerate(ctx.saved):
            g = np.empty(idx.shape[0])
            g[idx] = np.einsum("jnsd,njd->jns", V[k], gX[k])[act[k]]
            lam = np.zeros((j, n, 3))
            lam[act[k]] = lu.solve(g, trans="T")[idx]
            G = np.einsum("jns,jnsd->njd", lam, V[k]).reshape(n, 3 * j)
            Xf = Xn[k].reshape(n, 3 * j)
            # dL/dM = -G Xf^T.  M = L^T L + lambda1 L_sym  =>  dL/dL_out = L (dM + dM^T), dL/dL_sym = lambda1 dM.
            gL = -(L @ G) @ Xf.T - (L @ Xf) @ G.T
            gS = -ctx.lambda1 * (G @ Xf.T)
            # L = diag(A 1) - A  =>  dA_ij = dL_ii - dL_ij; L_sym from S = A + A^T likewise, then symmetrised.
            gA = np.diag(gL)[:, None] - gL
            gSA = np.diag(gS)[:, None] - gS
            grad_A[k] = gA + gSA + gSA.T
        return torch.as_tensor(grad_A, dtype=grad_X.dtype, device=grad_X.device), None, None


def solve_sparse(A: torch.Tensor, lambda1: float, sys: StructureSystem) -> torch.Tensor:
    """Sparse LU of all joints' systems at once (SuperLU, float64, CPU), differentiable w.r.t. A only.

    Args:
        A: Affinity, shape ``(B, N, N)``.
        lambda1: Weight of the symmetric Laplacian term.
        sys: The systems (their ``Ct``, ``W``, ``w`` must not need gradients).

    Returns:
        X, shape ``(B, N, J, 3)``, A's dtype and device.
    """
    X: torch.Tensor = _SparseSolve.apply(A, lambda1, sys)  # type: ignore[no-untyped-call]  # torch leaves it untyped
    return X
