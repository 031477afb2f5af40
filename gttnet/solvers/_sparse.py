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
    Within each joint the unknowns are numbered by image in ``order`` (default: image index), then slot.
    Joints whose every image has one unknown (slot 0: observed everywhere, pinned rays) come first: their
    blocks share M's pattern and are written straight in canonical CSC form, with no sort. The other
    joints (extra slots where unobserved, or a finite ray weight) follow, assembled from triplets.
    """
    j, n, _ = act.shape
    order = np.arange(n) if order is None else np.asarray(order)
    act_o, V_o = act[:, order], V[:, order]  # images in elimination order
    W_o = None if W is None else W[:, order]
    plain = ~act_o[:, :, 1:].any(axis=(1, 2))
    # number the unknowns: plain joints first, then the mixed ones; within a joint by image, then slot
    joint_order = np.r_[np.flatnonzero(plain), np.flatnonzero(~plain)]
    slots = np.full((j, n, 3), -1, dtype=np.int64)
    ranked = act_o[joint_order]
    numbered = np.full(ranked.shape, -1, dtype=np.int64)
    numbered[ranked] = np.arange(int(ranked.sum()))
    slots[joint_order] = numbered
    pos = np.full((j, n, 3), -1, dtype=np.int64)
    pos[:, order] = slots
    Mo = M[order][:, order].tocoo()
    diag = np.arange(n)
    # M's pattern with its diagonal (an image without links still carries its ray-weight terms there)
    P = sp.csc_matrix((np.r_[Mo.data, np.zeros(n)], (np.r_[Mo.row, diag], np.r_[Mo.col, diag])), shape=(n, n))
    P.sum_duplicates()
    ri, vals, ptr = P.indices, P.data, P.indptr
    ci = np.repeat(diag, np.diff(ptr))
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (data, indices, indptr) per part
    jp = np.flatnonzero(plain)
    if jp.size:
        V0 = np.ascontiguousarray(V_o[jp, :, 0].transpose(2, 0, 1))  # (3, Jp, N)
        data = (
            V0[0][:, ri] * V0[0][:, ci] + V0[1][:, ri] * V0[1][:, ci] + V0[2][:, ri] * V0[2][:, ci]
        ) * vals
        if W_o is not None:
            at = np.flatnonzero(ri == ci)  # the diagonal entry of every column, in column order
            v0 = V_o[jp, :, 0]
            data[:, at] += np.einsum("jna,jnab,jnb->jn", v0, W_o[jp], v0)
        # joint b's block: M's pattern shifted by b * N unknowns and b * nnz entries
        shift = np.arange(jp.size)[:, None]
        indptr = np.r_[(ptr[:-1][None, :] + shift * ri.size).ravel(), jp.size * ri.size]
        blocks.append((data.ravel(), (ri[None, :] + shift * n).ravel(), indptr))
    jm = np.flatnonzero(~plain)
    if jm.size:
        base = int(act_o[jp].sum())
        local = slots[jm] - base  # the mixed joints' unknowns, from 0, in elimination order of images
        Vm, am = V_o[jm], act_o[jm]
        data_l: list[np.ndarray] = [
            np.einsum("jkd,jkd->jk", Vm[:, ri, 0], Vm[:, ci, 0]).ravel() * np.tile(vals, jm.size)
        ]
        rows_l: list[np.ndarray] = [local[:, ri, 0].ravel()]
        cols_l: list[np.ndarray] = [local[:, ci, 0].ravel()]
        extra = np.asarray(am[:, :, 1:].any(-1))
        jj, kk = np.nonzero(extra[:, ri] | extra[:, ci])
        if jj.size:
            blk = Vm[jj, ri[kk]] @ Vm[jj, ci[kk]].transpose(0, 2, 1)
            blk *= vals[kk][:, None, None]
            blk[:, 0, 0] = 0.0  # slot-0 pairs are already counted above
            data_l.append(blk.ravel())
            rows_l.append(np.broadcast_to(local[jj, ri[kk]][:, :, None], blk.shape).ravel())
            cols_l.append(np.broadcast_to(local[jj, ci[kk]][:, None, :], blk.shape).ravel())
        if W_o is not None:
            D = Vm @ W_o[jm] @ Vm.transpose(0, 1, 3, 2)
            data_l.append(D.ravel())
            rows_l.append(np.broadcast_to(local[..., :, None], D.shape).ravel())
            cols_l.append(np.broadcast_to(local[..., None, :], D.shape).ravel())
        d, r, c = np.concatenate(data_l), np.concatenate(rows_l), np.concatenate(cols_l)
        keep = (r >= 0) & (c >= 0)
        size_m = int(am.sum())
        Hm = sp.csc_matrix((d[keep], (r[keep], c[keep])), shape=(size_m, size_m))
        Hm.sum_duplicates()
        blocks.append((Hm.data, Hm.indices + base, Hm.indptr))
    # stitch the parts: block-diagonal, so each part's CSC arrays shift by the unknowns and entries before it
    size = int(act.sum())
    data_all, idx_all, ptr_all = [], [], [np.zeros(1, dtype=np.int64)]
    nnz = 0
    for d_, i_, p_ in blocks:
        data_all.append(d_)
        idx_all.append(i_)
        ptr_all.append(p_[1:] + nnz)
        nnz += d_.size
    H = sp.csc_matrix(
        (np.concatenate(data_all), np.concatenate(idx_all), np.concatenate(ptr_all)), shape=(size, size)
    )
    return H, pos


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
