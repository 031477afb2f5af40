"""The DLOE X-step in numpy and SciPy only: the classical methods' path, which never imports torch.

:func:`solve_structure_np` solves the same objective as :func:`gttnet.solvers.xstep.solve_structure`
(docs/METHOD.md, section 4) with the same per-joint systems, assembled sparsely and factorised with SuperLU in
float64 (the torch module's ``"sparse"`` path runs the same assembly and factorisation: its forward calls
:func:`solve_item` below). It takes and returns numpy arrays and has no gradient. Importing torch costs about
a second of start-up, several times a 300-image DLOE run; ``gttnet reconstruct --method dloe`` (and pseudo,
dct, hpf, sync) therefore never load it (``tests/test_startup.py``).
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np

from gttnet.errors import SingularStructureError

if TYPE_CHECKING:
    import scipy.sparse as sp
    from scipy.sparse.linalg import SuperLU

__all__ = ["check_solvable", "noise_aware_lambda2", "solve_item", "solve_structure_np", "structure_diagonal"]

log = logging.getLogger(__name__)


def noise_aware_lambda2(sigma_px: float, f_px: float, depth_m: float, *, prior_std_m: float = 2e-3) -> float:
    """A finite ray weight lambda2 from the 2-D noise level (maximum a posteriori reasoning).

    A pixel error of ``sigma_px`` moves a point at ``depth_m`` off its ray by about
    ``s = sigma_px * depth_m / f_px`` metres per image axis. Reading the ray term and the Laplacian term
    as Gaussian negative log-likelihoods, with ``prior_std_m`` the per-coordinate spread the Laplacian
    term tolerates, and scaling by ``prior_std_m**2`` gives ``lambda2 = (prior_std_m / s)**2``.

    Calibration (true binary temporal chain, 4 cameras at 3 m, f = 1000 px, tests/fixtures/scenes.py):
    the best lambda2 over a 1e2..3e-2 grid is ~0.1-0.3 at 1 px, 0.1 at 2 px, 0.03-0.1 at 3 px and
    <= 0.03 at 5 px, which the default ``prior_std_m = 2 mm`` tracks (0.44, 0.11, 0.05, 0.018). The
    true ``L_out x`` residual there is only 0.4 mm rms: the effective spread is larger because
    neighbouring images' noise is correlated through the solve. MPJPE pinned -> noise-aware:
    4.6 -> 2.6 mm (1 px), 9.1 -> 4.2 mm (2 px), 13.6 -> 5.7 mm (3 px), 22.7 -> 9.2 mm (5 px).
    Recalibrate on real motion (faster than the synthetic body) before relying on the constant.
    For affinities whose rows are not O(1) (e.g. soft-max weights), scale ``prior_std_m`` by the row sum.

    Args:
        sigma_px: Std of the 2-D keypoint noise, pixels (> 0).
        f_px: Focal length, pixels.
        depth_m: Typical camera-to-subject distance, metres.
        prior_std_m: Std of the Laplacian residual of the true motion, metres.

    Returns:
        lambda2 (dimensionless, same units as the Laplacian terms).

    Example:
        >>> round(noise_aware_lambda2(1.0, 1000.0, 3.0, prior_std_m=3e-3), 6)
        1.0
    """
    if sigma_px <= 0 or f_px <= 0 or depth_m <= 0 or prior_std_m <= 0:
        raise ValueError(
            f"sigma_px, f_px, depth_m and prior_std_m must be > 0, got {sigma_px}, {f_px}, {depth_m}, {prior_std_m}"
        )
    s = sigma_px * depth_m / f_px
    return float((prior_std_m / s) ** 2)


def structure_diagonal(A: np.ndarray, lambda1: float) -> np.ndarray:
    """``diag(L_out^T L_out + lambda1 L_sym)`` of an affinity without forming the Laplacians, shape ``(..., N)``.

    Column m of ``L_out = diag(d) - A`` (``d = A 1``) has squared norm ``d_m^2 - 2 d_m A_mm + sum_n A_nm^2``;
    ``diag(L_sym) = d + A^T 1 - 2 diag(A)``.

    Args:
        A: Affinity, shape ``(..., N, N)``.
        lambda1: Weight of the symmetric Laplacian term.

    Example:
        >>> structure_diagonal(np.array([[0.0, 1.0], [0.0, 0.0]]), 0.0).tolist()
        [1.0, 1.0]
    """
    d = A.sum(-1)
    a = np.diagonal(A, axis1=-2, axis2=-1)
    out: np.ndarray = d * d - 2.0 * d * a + np.square(A).sum(-2) + lambda1 * (d + A.sum(-2) - 2.0 * a)
    return out


def check_solvable(A: np.ndarray, rays: np.ndarray, vis: np.ndarray, lambda1: float) -> None:
    """Raise SingularStructureError where a graph component does not pin down a joint.

    A component of the (undirected) link graph fixes joint p only if its observed rays of p span at
    least two directions; otherwise the solution can slide (translation / depth) at zero cost.

    Args:
        A: Affinities, shape ``(B, N, N)``.
        rays: Unit rays, shape ``(B, N, J, 3)``.
        vis: Observed-joint mask, shape ``(B, N, J)``.
        lambda1: Weight of the symmetric Laplacian term (0 only makes the check optimistic).
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    if lambda1 == 0:
        log.debug("lambda1 = 0: solvability checked on undirected components, which may be optimistic")
    Ab = A != 0
    for b in range(Ab.shape[0]):
        ncomp, label = connected_components(csr_matrix(Ab[b] | Ab[b].T), directed=False)
        rr = np.where(vis[b][..., None], rays[b], 0.0)
        S = np.zeros((ncomp, rays.shape[2], 3, 3))
        np.add.at(S, label, np.einsum("nja,njb->njab", rr, rr))
        tr = np.trace(S, axis1=-2, axis2=-1)
        e2 = 0.5 * (tr**2 - np.sum(S * S, axis=(-2, -1)))
        bad = np.argwhere(e2 <= 1e-10)
        if bad.size:
            c, p = bad[0]
            size = int(np.sum(label == c))
            raise SingularStructureError(
                f"X-step is singular: joint {p} is observed along fewer than two ray directions in a linked "
                f"component of {size} images (batch {b}); pass x_prior (e.g. X_init) to regularise"
            )


def _laplacians_np(A: np.ndarray, lambda1: float) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Sparse ``L_out`` and ``M = L_out^T L_out + lambda1 L_sym`` of one dense affinity ``(N, N)``."""
    import scipy.sparse as sp

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
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

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
    import scipy.sparse as sp

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


def solve_item(
    A: np.ndarray,
    lambda1: float,
    V: np.ndarray,
    act: np.ndarray,
    Ct: np.ndarray,
    W: np.ndarray | None,
    w: np.ndarray | None,
    *,
    item: int = 0,
) -> tuple[np.ndarray, SuperLU, sp.csr_matrix, np.ndarray]:
    """Assemble and factorise the J systems of one batch item, and solve them.

    Args:
        A: Affinity, shape ``(N, N)``, float64.
        lambda1: Weight of the symmetric Laplacian term.
        V: Slot directions, shape ``(J, N, 3, 3)`` (zero where inactive).
        act: Active slots, shape ``(J, N, 3)`` bool.
        Ct: Fixed offset of each point, metres, shape ``(J, N, 3)``.
        W: Per-image quadratic weight, shape ``(J, N, 3, 3)``, or None.
        w: Per-image linear weight, shape ``(J, N, 3)``, or None (given with W).
        item: Batch index, for the error message.

    Returns:
        ``(z, lu, L_out, idx)``: slot values ``(J, N, 3)`` (zero where inactive), the SuperLU factor, the
        sparse out-degree Laplacian and each active slot's unknown (for an adjoint solve).

    Raises:
        SingularStructureError: If the factorisation meets a singular system.
    """
    from scipy.sparse.linalg import splu

    j, n, _ = act.shape
    L, M = _laplacians_np(A, lambda1)
    H, pos = _assemble(M, V, act, W, order=_image_order(M))
    q = -(M @ Ct.transpose(1, 0, 2).reshape(n, 3 * j)).reshape(n, j, 3).transpose(1, 0, 2)
    if W is not None and w is not None:
        q += w - (W @ Ct[..., None])[..., 0]
    idx = pos[act]  # each active slot's unknown, in the mask's (joint, image, slot) order
    rhs = np.empty(idx.shape[0])
    rhs[idx] = np.einsum("jnsd,jnd->jns", V, q)[act]
    try:
        # H is symmetric positive (semi)definite: a symmetric ordering with diagonal pivots
        # preferred keeps the fill near that of a Cholesky factor. With the partial-sequencing
        # chain (300 images, 31 joints) it factorises in 11 ms against 19 ms for plain threshold
        # pivoting (L + U 261k against 365k entries); without it both take about 2.5 ms. The
        # unknowns already come in a fill-reducing order (_image_order), so SuperLU keeps it.
        lu = splu(H, permc_spec="NATURAL", diag_pivot_thresh=0.1, options={"SymmetricMode": True})
    except RuntimeError as exc:
        raise SingularStructureError(f"X-step system of batch item {item} is singular: {exc}") from exc
    z = np.zeros((j, n, 3))
    z[act] = lu.solve(rhs)[idx]
    return z, lu, L, idx


def _system_np(
    C: np.ndarray,
    r: np.ndarray,
    vis: np.ndarray,
    lam: np.ndarray | None,
    xp: np.ndarray | None,
    eps: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Slots ``V (B, J, N, 3, 3)``, ``active (B, J, N, 3)``, ``Ct (B, J, N, 3)``, ``W``, ``w`` (see ``_system``)."""
    b, n, j, _ = r.shape
    rJ = r.transpose(0, 2, 1, 3)  # (B, J, N, 3)
    vJ = vis.transpose(0, 2, 1)  # (B, J, N)
    CJ = np.broadcast_to(C[:, None], (b, j, n, 3))
    eye = np.eye(3)
    W: np.ndarray | None = None
    w: np.ndarray | None = None
    if lam is None:
        act = np.stack([np.ones_like(vJ), ~vJ, ~vJ], -1)
        V = np.empty((b, j, n, 3, 3))
        V[..., 0, :] = np.where(vJ[..., None], rJ, eye[0])
        V[..., 1:, :] = eye[1:]
        Ct = np.where(vJ[..., None], CJ, 0.0)
    else:
        act = np.ones((b, j, n, 3), dtype=bool)
        V = np.broadcast_to(eye, (b, j, n, 3, 3)).copy()
        Ct = np.zeros((b, j, n, 3))
        P = (eye - rJ[..., :, None] * rJ[..., None, :]) * vJ[..., None, None]
        lamJ = lam[:, None, :, None]  # (B, 1, N, 1)
        W = lamJ[..., None] * P
        w = lamJ * (P @ CJ[..., None])[..., 0]
    V *= act[..., None]
    if xp is not None:
        e = eps[:, None, None, None]
        ridge = e[..., None] * eye
        W = np.broadcast_to(ridge, (b, j, n, 3, 3)) if W is None else W + ridge
        xpJ = xp.transpose(0, 2, 1, 3)
        w = e * xpJ if w is None else w + e * xpJ
    return V, act, Ct, W, w


def solve_structure_np(
    A: np.ndarray,
    centers: np.ndarray,
    rays: np.ndarray,
    visible: np.ndarray,
    *,
    lambda1: float = 0.1,
    lambda2: float | np.ndarray | None = None,
    x_prior: np.ndarray | None = None,
    prior_weight: float = 1e-6,
) -> np.ndarray:
    """Structure X minimising the DLOE objective for a given affinity, in numpy (float64, SuperLU).

    The objective, the pinned limit (``lambda2=None``), the ridge toward ``x_prior`` and the solvability
    check are those of :func:`gttnet.solvers.xstep.solve_structure`; this is its ``"sparse"`` path without
    torch (equal to it to rounding, and to its dense path to the factorisations' rounding). No gradients.

    Args:
        A: Affinity, shape ``(N, N)`` or ``(B, N, N)``, non-negative; row n weights image n's links.
        centers: Camera centre of each image in world, metres, shape ``(N, 3)`` or ``(B, N, 3)``.
        rays: Viewing rays in world, shape ``(N, J, 3)`` or ``(B, N, J, 3)``; normalised here.
        visible: Observed-joint mask, shape ``(N, J)`` or ``(B, N, J)``.
        lambda1: Weight of the symmetric Laplacian term.
        lambda2: Ray weight: a number, one per image ``(N,)`` or ``(B, N)``; None for the pinned limit.
        x_prior: Optional fallback structure, metres, shape ``(N, J, 3)`` or ``(B, N, J, 3)``.
        prior_weight: Relative ridge weight toward ``x_prior``.

    Returns:
        X in world, metres, shape ``(N, J, 3)`` (``(B, N, J, 3)`` when any input is batched), float64.

    Raises:
        SingularStructureError: If the solution is not unique and no ``x_prior`` is given.
        ValueError: For inputs of the wrong shape, negative or non-finite values, or zero rays.

    Example:
        >>> C = np.array([[0.0, -1, 0], [0.0, 1, 0]])
        >>> r = np.array([[[0.0, 1, 1]], [[0.0, -1, 1]]])
        >>> A = np.array([[0.0, 1.0], [1.0, 0.0]])
        >>> np.abs(solve_structure_np(A, C, r, np.ones((2, 1), bool))).round(5).tolist()
        [[[0.0, 0.0, 1.0]], [[0.0, 0.0, 1.0]]]
    """
    A = np.asarray(A, dtype=np.float64)
    if A.ndim not in (2, 3) or A.shape[-1] != A.shape[-2]:
        raise ValueError(f"A must have shape (N, N) or (B, N, N), got {A.shape}")
    C = np.asarray(centers, dtype=np.float64)
    r = np.asarray(rays, dtype=np.float64)
    vis = np.asarray(visible).astype(bool)
    n, j = A.shape[-1], vis.shape[-1]
    if C.shape[-2:] != (n, 3) or r.shape[-3:] != (n, j, 3) or vis.shape[-2:] != (n, j):
        raise ValueError(
            f"expected centers (N, 3), rays (N, J, 3), visible (N, J) with N={n} from A; got "
            f"{C.shape}, {r.shape}, {vis.shape}"
        )
    batched = A.ndim == 3 or C.ndim == 3 or r.ndim == 4 or vis.ndim == 3
    b = max(
        A.shape[0] if A.ndim == 3 else 1, C.shape[0] if C.ndim == 3 else 1, r.shape[0] if r.ndim == 4 else 1
    )
    A3 = np.broadcast_to(A, (b, n, n))
    C3 = np.broadcast_to(C, (b, n, 3))
    v3 = np.broadcast_to(vis, (b, n, j))
    r4 = np.where(v3[..., None], np.broadcast_to(r, (b, n, j, 3)), 0.0)
    if not (np.isfinite(A3).all() and np.isfinite(C3).all() and np.isfinite(r4).all()):
        raise ValueError("A, centers and the visible rays must be finite")
    norm = np.linalg.norm(r4, axis=-1, keepdims=True)
    if bool((v3 & (norm[..., 0] == 0)).any()):
        raise ValueError("every visible joint needs a non-zero ray")
    r4 = r4 / np.where(v3[..., None], norm, 1.0)  # unit rays (P = I - r r^T needs it)
    if (A3 < 0).any():
        raise ValueError("A must be non-negative")
    if lambda1 < 0:
        raise ValueError(f"need lambda1 >= 0, got {lambda1}")
    lam = None
    if lambda2 is not None:
        lam = np.asarray(lambda2, dtype=np.float64)
        if not bool(np.all(lam > 0)) or not bool(np.all(np.isfinite(lam))):
            raise ValueError(f"need lambda2 > 0 and finite (or None), got {lambda2}")
        if lam.ndim and lam.shape not in ((n,), (b, n)):
            raise ValueError(f"lambda2 must be a number or have shape ({n},) or ({b}, {n}), got {lam.shape}")
        lam = np.broadcast_to(lam, (b, n))
    xp = None
    eps = np.zeros(b)
    if x_prior is None:
        check_solvable(A3, r4, v3, lambda1)
    else:
        xp = np.broadcast_to(np.asarray(x_prior, dtype=np.float64), (b, n, j, 3))
        eps = prior_weight * (structure_diagonal(A3, lambda1).mean(-1) + 1e-12)
    V, act, Ct, W, w = _system_np(C3, r4, v3, lam, xp, eps)
    X = np.empty((b, n, j, 3))
    for k in range(b):
        z, *_ = solve_item(A3[k], lambda1, V[k], act[k], Ct[k], None if W is None else W[k],
                           None if w is None else w[k], item=k)  # fmt: skip
        X[k] = (Ct[k] + (z[..., None] * V[k]).sum(-2)).transpose(1, 0, 2)
    return X if batched else X[0]
