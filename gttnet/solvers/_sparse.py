"""Sparse CPU path of the X-step: SuperLU on the block-diagonal system of all joints, with a custom backward."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import scipy.sparse as sp
import torch
from scipy.sparse.linalg import splu

from gttnet.errors import SingularStructureError
from gttnet.solvers._system import StructureSystem

__all__ = ["solve_sparse"]

log = logging.getLogger(__name__)


def _laplacians_np(A: np.ndarray, lambda1: float) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Sparse ``L_out`` and ``M = L_out^T L_out + lambda1 L_sym`` of one dense affinity ``(N, N)``."""
    As = sp.csr_matrix(A)
    L = (sp.diags(np.asarray(As.sum(1)).ravel()) - As).tocsr()
    S = As + As.T
    Ls = sp.diags(np.asarray(S.sum(1)).ravel()) - S
    return L, (L.T @ L + lambda1 * Ls).tocsr()


def _image_order(M: sp.csr_matrix) -> np.ndarray:
    """A fill-reducing elimination order of the images, shape ``(N,)``: minimum degree on ``M + I``.

    Every joint's system has M's pattern (plus diagonal slot blocks), so one ordering of the N images
    serves all J systems; ordering the whole block-diagonal matrix instead repeats the same work J
    times (at 300 images and 31 joints the factorisation took 20-25 % longer, with the same fill).
    The identity only makes the matrix definite: an image without links leaves M singular.
    """
    n = M.shape[0]
    P = sp.csc_matrix(abs(M) + sp.identity(n, format="csr"))
    # perm_c[i] is the position SuperLU moved column i to; the images in elimination order are its inverse
    order: np.ndarray = np.argsort(
        splu(P, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True}).perm_c
    )
    return order


def _assemble(
    M: sp.csr_matrix, V: np.ndarray, act: np.ndarray, W: np.ndarray | None, order: np.ndarray | None = None
) -> tuple[sp.csc_matrix, np.ndarray]:
    """Block-diagonal matrix of the J systems of one batch item; returns it and the unknown index (J, N, 3).

    Entry (a, b) for unknowns at images n, m is ``M[n, m] v_a . v_b`` plus, when n = m, ``v_a^T W_n v_b``.
    Slot 0 of every image is always an unknown, so the slot-0 pairs are one vectorised dot product; the
    full 3 x 3 slot blocks are formed only for the image pairs where either side has extra slots.
    Within each joint the unknowns are numbered by image in ``order`` (default: image index), then slot.
    """
    j, n, _ = act.shape
    pos = np.full((j, n, 3), -1, dtype=np.int64)
    if order is None:
        pos[act] = np.arange(int(act.sum()))
    else:
        ranked = act[:, order]  # (J, N, 3) with the images in elimination order
        slots = np.full((j, n, 3), -1, dtype=np.int64)
        slots[ranked] = np.arange(int(act.sum()))
        pos[:, order] = slots
    Mc = M.tocoo()
    ri, ci, vals = Mc.row, Mc.col, Mc.data
    V0 = V[:, :, 0]
    data: list[np.ndarray] = [np.einsum("jkd,jkd->jk", V0[:, ri], V0[:, ci]).ravel() * np.tile(vals, j)]
    rows: list[np.ndarray] = [pos[:, ri, 0].ravel()]
    cols: list[np.ndarray] = [pos[:, ci, 0].ravel()]
    extra = np.asarray(act[:, :, 1:].any(-1))
    jj, kk = np.nonzero(extra[:, ri] | extra[:, ci])
    if jj.size:
        blk = V[jj, ri[kk]] @ V[jj, ci[kk]].transpose(0, 2, 1)
        blk *= vals[kk][:, None, None]
        blk[:, 0, 0] = 0.0  # slot-0 pairs are already counted above
        data.append(blk.ravel())
        rows.append(np.broadcast_to(pos[jj, ri[kk]][:, :, None], blk.shape).ravel())
        cols.append(np.broadcast_to(pos[jj, ci[kk]][:, None, :], blk.shape).ravel())
    if W is not None:
        D = V @ W @ V.transpose(0, 1, 3, 2)
        data.append(D.ravel())
        rows.append(np.broadcast_to(pos[..., :, None], D.shape).ravel())
        cols.append(np.broadcast_to(pos[..., None, :], D.shape).ravel())
    d, r, c = np.concatenate(data), np.concatenate(rows), np.concatenate(cols)
    keep = (r >= 0) & (c >= 0)
    size = int(act.sum())
    return sp.csc_matrix((d[keep], (r[keep], c[keep])), shape=(size, size)), pos


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
            L, M = _laplacians_np(An[k], lambda1)
            H, pos = _assemble(M, V[k], act[k], None if W is None else W[k], order=_image_order(M))
            q = -(M @ Ct[k].transpose(1, 0, 2).reshape(n, 3 * j)).reshape(n, j, 3).transpose(1, 0, 2)
            if W is not None:
                assert w is not None  # the ray-weighted system always carries both
                q += w[k] - (W[k] @ Ct[k][..., None])[..., 0]
            idx = pos[act[k]]  # each active slot's unknown, in the mask's (joint, image, slot) order
            rhs = np.empty(idx.shape[0])
            rhs[idx] = np.einsum("jnsd,jnd->jns", V[k], q)[act[k]]
            try:
                # H is symmetric positive (semi)definite: a symmetric ordering with diagonal pivots
                # preferred keeps the fill near that of a Cholesky factor. With the partial-sequencing
                # chain (300 images, 31 joints) it factorises in 11 ms against 19 ms for plain threshold
                # pivoting (L + U 261k against 365k entries); without it both take about 2.5 ms. The
                # unknowns already come in a fill-reducing order (_image_order), so SuperLU keeps it.
                lu = splu(H, permc_spec="NATURAL", diag_pivot_thresh=0.1, options={"SymmetricMode": True})
            except RuntimeError as exc:
                raise SingularStructureError(f"X-step system of batch item {k} is singular: {exc}") from exc
            zs[k][act[k]] = lu.solve(rhs)[idx]
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
