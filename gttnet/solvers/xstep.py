"""The DLOE X-step: 3D structure from an affinity graph and the viewing rays, as a differentiable solve."""

from __future__ import annotations

import logging
from typing import TypeAlias

import numpy.typing as npt
import torch

from gttnet.errors import SingularStructureError
from gttnet.solvers._sparse import solve_sparse
from gttnet.solvers._system import build_system, solve_dense
from gttnet.solvers.numpy_xstep import check_solvable, noise_aware_lambda2

#: Centres, rays, masks and priors: tensors, or anything ``torch.as_tensor`` takes.
ArrayIn: TypeAlias = "torch.Tensor | npt.ArrayLike"

__all__ = [
    "DLOESolver",
    "SingularStructureError",
    "laplacians",
    "noise_aware_lambda2",
    "solve_structure",
    "solve_structure_dense",
    "structure_energy",
]

log = logging.getLogger(__name__)

_METHODS = ("auto", "dense", "sparse")
#: N from which ``method="auto"`` uses the sparse CPU path. benchmarks/bench_xstep.py (J = 31, Q ~ 3):
#: with one thread sparse wins from N ~ 100 (N = 200: 0.044 s vs 0.076 s dense); with 16 threads the
#: dense path wins up to N ~ 500, so this is a compromise aimed at small machines.
SPARSE_FROM_N = 200
#: Largest fraction of non-zero affinity entries for which ``"auto"`` picks the sparse path: the
#: factorisation's fill grows with the density, and a dense A (e.g. A^D before top-Q) is faster dense.
SPARSE_MAX_DENSITY = 0.05


def laplacians(A: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Out-degree and symmetrised Laplacians of an affinity.

    Args:
        A: Non-negative affinity, shape ``(..., N, N)``; row n holds the weights of image n's links.

    Returns:
        ``(L_out, L_sym)``: ``diag(A 1) - A`` and ``diag((A + A^T) 1) - (A + A^T)``, shape ``(..., N, N)``.

    Example:
        >>> L_out, L_sym = laplacians(torch.tensor([[0.0, 1.0], [0.0, 0.0]]))
        >>> L_out.tolist(), L_sym.tolist()
        ([[1.0, -1.0], [0.0, 0.0]], [[1.0, -1.0], [-1.0, 1.0]])
    """
    S = A + A.transpose(-1, -2)
    L_out = torch.diag_embed(A.sum(-1)) - A
    L_sym = torch.diag_embed(S.sum(-1)) - S
    return L_out, L_sym


def _structure_diagonal(A: torch.Tensor, lambda1: float) -> torch.Tensor:
    """``diag(M)`` of :func:`_structure_matrix` without forming the ``N x N`` Laplacians, shape ``(..., N)``.

    Column m of ``L_out = diag(d) - A`` (``d = A 1``) has squared norm ``d_m^2 - 2 d_m A_mm + sum_n A_nm^2``;
    ``diag(L_sym) = d + A^T 1 - 2 diag(A)``.
    """
    d = A.sum(-1)
    a = torch.diagonal(A, dim1=-2, dim2=-1)
    return d * d - 2.0 * d * a + A.square().sum(-2) + lambda1 * (d + A.sum(-2) - 2.0 * a)


def _structure_matrix(A: torch.Tensor, lambda1: float) -> torch.Tensor:
    """``M = L_out^T L_out + lambda1 L_sym``: the Laplacian part of the objective, per coordinate."""
    L_out, L_sym = laplacians(A)
    return L_out.transpose(-1, -2) @ L_out + lambda1 * L_sym


def _as_inputs(
    A: torch.Tensor, centers: ArrayIn, rays: ArrayIn, visible: ArrayIn, x_prior: ArrayIn | None
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor | None, bool]:
    """Validate and convert to tensors on A's device and dtype, all with a leading batch axis."""
    if not torch.is_tensor(A):
        raise TypeError(f"A must be a torch tensor, got {type(A).__name__}")
    if A.ndim not in (2, 3) or A.shape[-1] != A.shape[-2]:
        raise ValueError(f"A must have shape (N, N) or (B, N, N), got {tuple(A.shape)}")
    batched = A.ndim == 3
    dt, dev = A.dtype, A.device
    C = torch.as_tensor(centers, dtype=dt, device=dev)
    r = torch.as_tensor(rays, dtype=dt, device=dev)
    vis = torch.as_tensor(visible, device=A.device).bool()
    n = A.shape[-1]
    j = vis.shape[-1]
    if C.shape[-2:] != (n, 3) or r.shape[-3:] != (n, j, 3) or vis.shape[-2:] != (n, j):
        raise ValueError(
            f"expected centers (N, 3), rays (N, J, 3), visible (N, J) with N={n} from A; got "
            f"{tuple(C.shape)}, {tuple(r.shape)}, {tuple(vis.shape)}"
        )
    if C.ndim == 3 or r.ndim == 4 or vis.ndim == 3:
        batched = True
    b = max(
        A.shape[0] if A.ndim == 3 else 1, C.shape[0] if C.ndim == 3 else 1, r.shape[0] if r.ndim == 4 else 1
    )
    A3 = A.expand(b, n, n) if A.ndim == 3 else A.unsqueeze(0).expand(b, n, n)
    C3 = C.expand(b, n, 3) if C.ndim == 3 else C.unsqueeze(0).expand(b, n, 3)
    r4 = r.expand(b, n, j, 3) if r.ndim == 4 else r.unsqueeze(0).expand(b, n, j, 3)
    v3 = vis.expand(b, n, j) if vis.ndim == 3 else vis.unsqueeze(0).expand(b, n, j)
    r4 = torch.where(v3.unsqueeze(-1), r4, torch.zeros((), dtype=dt, device=dev))
    if not (torch.isfinite(A).all() and torch.isfinite(C).all() and torch.isfinite(r4).all()):
        raise ValueError("A, centers and the visible rays must be finite")
    norm = r4.norm(dim=-1, keepdim=True)
    if bool((v3 & (norm[..., 0] == 0)).any()):
        raise ValueError("every visible joint needs a non-zero ray")
    r4 = r4 / torch.where(
        v3.unsqueeze(-1), norm, torch.ones((), dtype=dt, device=dev)
    )  # unit rays (P = I - r r^T needs it)
    xp = None
    if x_prior is not None:
        xp = torch.as_tensor(x_prior, dtype=dt, device=dev)
        xp = xp.expand(b, n, j, 3) if xp.ndim == 4 else xp.unsqueeze(0).expand(b, n, j, 3)
    return A3, C3, r4, v3, xp, batched


def _check_solvable(A: torch.Tensor, rays: torch.Tensor, vis: torch.Tensor, lambda1: float) -> None:
    """Raise SingularStructureError where a graph component does not pin down a joint (see ``numpy_xstep``)."""
    check_solvable(
        (A.detach() != 0).cpu().numpy(), rays.detach().double().cpu().numpy(), vis.cpu().numpy(), lambda1
    )


def _solve(
    A: torch.Tensor,
    centers: ArrayIn,
    rays: ArrayIn,
    visible: ArrayIn,
    *,
    lambda1: float,
    lambda2: float | ArrayIn | None,
    method: str,
    x_prior: ArrayIn | None,
    prior_weight: float,
) -> torch.Tensor:
    if method not in _METHODS:
        raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
    lam: torch.Tensor | None = None
    if lambda2 is not None:
        lam = torch.as_tensor(lambda2, dtype=torch.float64).detach()
        if not bool(torch.all(lam > 0)) or not bool(torch.all(torch.isfinite(lam))):
            raise ValueError(f"need lambda2 > 0 and finite (or None), got {lambda2}")
    if lambda1 < 0:
        raise ValueError(f"need lambda1 >= 0, got {lambda1}")
    A3, C, r, vis, xp, batched = _as_inputs(A, centers, rays, visible, x_prior)
    if (A3.detach() < 0).any():
        raise ValueError("A must be non-negative")
    if xp is None:
        _check_solvable(A3, r, vis, lambda1)
    n = A3.shape[-1]
    if method == "auto":
        needs_geom_grad = torch.is_grad_enabled() and (r.requires_grad or C.requires_grad)
        sparse_ok = A3.device.type == "cpu" and n >= SPARSE_FROM_N and not needs_geom_grad
        sparse_ok = sparse_ok and int(torch.count_nonzero(A3.detach())) <= SPARSE_MAX_DENSITY * A3.numel()
        method = "sparse" if sparse_ok else "dense"
    if method == "sparse" and torch.is_grad_enabled() and (r.requires_grad or C.requires_grad):
        raise ValueError("method 'sparse' differentiates w.r.t. A only; use method='dense' for ray gradients")
    eps = None
    if xp is not None:
        with torch.no_grad():  # a constant in backward
            diag = _structure_diagonal(A3, lambda1)
            eps = prior_weight * (diag.mean(-1) + 1e-12)
    sys = build_system(C, r, vis, lambda2=lam, x_prior=xp, eps=eps)
    X = (
        solve_sparse(A3, lambda1, sys)
        if method == "sparse"
        else solve_dense(_structure_matrix(A3, lambda1), sys)
    )
    return X if batched else X[0]


def solve_structure(
    A: torch.Tensor,
    centers: ArrayIn,
    rays: ArrayIn,
    visible: ArrayIn,
    *,
    lambda1: float = 0.1,
    lambda2: float | ArrayIn | None = None,
    method: str = "auto",
    x_prior: ArrayIn | None = None,
    prior_weight: float = 1e-6,
) -> torch.Tensor:
    """Structure X minimising the DLOE objective for a given affinity (docs/METHOD.md, section 4).

    Per joint and coordinate c: ``|L_out x_c|^2 + lambda1 x_c^T L_sym x_c`` plus
    ``lambda2 sum_n |(I - r r^T)(X_n - C_n)|^2`` over observed images (all terms / (N J), which does
    not move the minimiser). ``lambda2=None`` is the pinned limit: observed joints are ``C_n + d r_n``
    and the exact minimiser is found over the depths d (one unknown per observed joint, three per missing
    joint, which the Laplacian terms fill). A finite lambda2 solves the full 3N system per joint,
    letting points leave their rays (see :func:`noise_aware_lambda2`).

    ``method``: ``"dense"`` batches one Cholesky solve per joint (and per batch item) with torch.linalg;
    ``"sparse"`` assembles each joint's system sparsely and factorises it with SuperLU on CPU in float64
    (differentiable w.r.t. A through a custom backward, not w.r.t. rays or centres); ``"auto"`` uses
    sparse on CPU from N = :data:`SPARSE_FROM_N` when at most :data:`SPARSE_MAX_DENSITY` of A is
    non-zero, dense otherwise. Gradients flow to ``A``.

    A unique solution needs every joint observed along two or more ray directions in every linked
    component of the graph. Without ``x_prior`` this is checked and :class:`SingularStructureError` is
    raised. With ``x_prior`` a ridge ``eps |X - x_prior|^2`` is added to every image and joint, with
    ``eps = prior_weight * mean(diag(M))`` (M the Laplacian part; treated as a constant in backward),
    small enough to leave well-posed solutions unchanged to ~``prior_weight`` relative.

    Args:
        A: Affinity, shape ``(N, N)`` or ``(B, N, N)``, non-negative; row n weights image n's links.
        centers: Camera centre of each image in world, metres, shape ``(N, 3)`` or ``(B, N, 3)``.
        rays: Viewing rays in world, shape ``(N, J, 3)`` or ``(B, N, J, 3)``; normalised here.
        visible: Observed-joint mask, shape ``(N, J)`` or ``(B, N, J)``.
        lambda1: Weight of the symmetric Laplacian term (0.1 in GTT-Net training, 0.0015 in DLOE).
        lambda2: Ray weight: a number, or one per image (shape ``(N,)``, batched ``(B, N)``: e.g. the
            noise-aware weight at each image's own depth); None for the pinned limit lambda2 -> inf.
        method: ``"auto"``, ``"dense"`` or ``"sparse"``.
        x_prior: Optional fallback structure (e.g. X_init), metres, shape ``(N, J, 3)`` or ``(B, N, J, 3)``.
        prior_weight: Relative ridge weight toward ``x_prior``.

    Returns:
        X in world, metres, shape ``(N, J, 3)`` (``(B, N, J, 3)`` when any input is batched), A's dtype.

    Raises:
        SingularStructureError: If the solution is not unique and no ``x_prior`` is given.

    Example:
        >>> C = torch.tensor([[0.0, -1, 0], [0.0, 1, 0]])
        >>> r = torch.tensor([[[0.0, 1, 1]], [[0.0, -1, 1]]]) / 2**0.5
        >>> A = torch.tensor([[0.0, 1.0], [1.0, 0.0]])
        >>> solve_structure(A, C, r, torch.ones(2, 1, dtype=torch.bool)).round(decimals=5).abs().tolist()
        [[[0.0, 0.0, 1.0]], [[0.0, 0.0, 1.0]]]
    """
    return _solve(
        A, centers, rays, visible, lambda1=lambda1, lambda2=lambda2, method=method, x_prior=x_prior,
        prior_weight=prior_weight,
    )  # fmt: skip


def solve_structure_dense(
    A: torch.Tensor,
    centers: ArrayIn,
    rays: ArrayIn,
    visible: ArrayIn,
    *,
    lambda1: float = 0.1,
    lambda2: float = 1e10,
) -> torch.Tensor:
    """Reference X-step as in the published code: a dense 3N x 3N solve per joint (slow; for tests).

    Builds ``H = kron(M, I_3) + lambda2 blockdiag(P_n)`` with ``P_n = I - r r^T`` for observed joints and
    solves ``H x = lambda2 [P_n C_n]`` by LU for every joint at once. Conditioning: H's condition number
    grows like lambda2 / lambda_min(M). Measured against the exact pinned solution (float64, N = 12,
    random well-posed case), the relative error is 1.4e-3 at lambda2 = 1e4 (the model error ~1/lambda2),
    1.4e-7 at 1e8 (best), then rises from rounding: 1.1e-6 at the reference's 1e10, 1e-4 at 1e12 and
    1e-2 at 1e14. The pinned reduction has neither error.

    Args:
        A: Affinity, shape ``(N, N)`` or ``(B, N, N)``.
        centers: Camera centres, metres, shape ``(N, 3)``.
        rays: Unit rays, shape ``(N, J, 3)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        lambda1: Weight of the symmetric Laplacian term.
        lambda2: Ray weight.

    Returns:
        X in world, metres, shape ``(N, J, 3)`` or ``(B, N, J, 3)``.

    Example:
        >>> C = torch.tensor([[0.0, -1, 0], [0.0, 1, 0]], dtype=torch.float64)
        >>> r = torch.tensor([[[0.0, 1, 1]], [[0.0, -1, 1]]], dtype=torch.float64) / 2**0.5
        >>> A = torch.tensor([[0.0, 1.0], [1.0, 0.0]], dtype=torch.float64)
        >>> X = solve_structure_dense(A, C, r, torch.ones(2, 1, dtype=torch.bool))
        >>> bool(torch.allclose(X, torch.tensor([0.0, 0, 1], dtype=torch.float64), atol=1e-5))  # ~1e-6 off: cond(H)
        True
    """
    A3, C, r, vis, _, batched = _as_inputs(A, centers, rays, visible, None)
    b, n, j, _ = r.shape
    M = _structure_matrix(A3, lambda1)  # (B, N, N)
    eye = torch.eye(3, dtype=A3.dtype, device=A3.device)
    P = (eye - r.unsqueeze(-1) * r.unsqueeze(-2)) * vis[..., None, None]  # (B, N, J, 3, 3)
    P = P.permute(0, 2, 1, 3, 4)  # (B, J, N, 3, 3)
    H = torch.kron(M, eye).unsqueeze(1).repeat(1, j, 1, 1)  # (B, J, 3N, 3N)
    Hv = H.view(b, j, n, 3, n, 3)
    idx = torch.arange(n, device=A3.device)
    Hv[:, :, idx, :, idx, :] = Hv[:, :, idx, :, idx, :] + lambda2 * P.permute(2, 0, 1, 3, 4)
    rhs = lambda2 * (P @ C.unsqueeze(1).unsqueeze(-1)).reshape(b, j, 3 * n, 1)
    x: torch.Tensor = torch.linalg.solve(H, rhs).reshape(b, j, n, 3).transpose(1, 2)
    return x if batched else x[0]


def structure_energy(
    A: torch.Tensor, X: torch.Tensor, *, lambda1: float = 0.1, centers: ArrayIn | None = None,
    rays: ArrayIn | None = None, visible: ArrayIn | None = None, lambda2: float | None = None,
) -> torch.Tensor:  # fmt: skip
    """The DLOE objective divided by N J; without rays it is the smoothness loss (paper's l^S).

    Args:
        A: Affinity, shape ``(N, N)`` or ``(B, N, N)``.
        X: Structure in world, metres, shape ``(N, J, 3)`` or ``(B, N, J, 3)``.
        lambda1: Weight of the symmetric Laplacian term.
        centers: Camera centres, shape ``(N, 3)``; with ``rays``, ``visible`` and ``lambda2``, adds the ray term.
        rays: Unit rays, shape ``(N, J, 3)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        lambda2: Ray weight (required for the ray term).

    Returns:
        Energy, shape ``()`` or ``(B,)``.

    Example:
        >>> A = torch.tensor([[0.0, 1.0], [1.0, 0.0]])
        >>> float(structure_energy(A, torch.zeros(2, 1, 3)))
        0.0
    """
    L_out, L_sym = laplacians(A)
    n, j = X.shape[-3], X.shape[-2]
    x = X.flatten(-2)  # (..., N, 3J): every coordinate column at once
    e = (L_out @ x).square().sum((-2, -1)) + lambda1 * (x * (L_sym @ x)).sum((-2, -1))
    if rays is not None:
        if lambda2 is None or centers is None or visible is None:
            raise ValueError("the ray term needs centers, rays, visible and a finite lambda2")
        r = torch.as_tensor(rays, dtype=X.dtype, device=X.device)
        d = X - torch.as_tensor(centers, dtype=X.dtype, device=X.device).unsqueeze(-2)
        perp = d - (d * r).sum(-1, keepdim=True) * r
        vis = torch.as_tensor(visible, device=X.device).bool()
        e = e + lambda2 * (perp.square().sum(-1) * vis).sum((-2, -1))
    return e / (n * j)


class DLOESolver(torch.nn.Module):
    """The DLOE layer: affinity -> structure, differentiable w.r.t. the affinity.

    Args:
        lambda1: Weight of the symmetric Laplacian term (keep train and test identical).
        lambda2: Ray weight; None pins observed joints to their rays.
        method: Solver path, see :func:`solve_structure`.
        prior_weight: Relative ridge weight toward ``x_prior`` when one is passed.

    Example:
        >>> solver = DLOESolver(lambda1=0.1)
        >>> C = torch.tensor([[0.0, -1, 0], [0.0, 1, 0]])
        >>> r = torch.tensor([[[0.0, 1, 1]], [[0.0, -1, 1]]]) / 2**0.5
        >>> solver(torch.ones(2, 2) - torch.eye(2), C, r, torch.ones(2, 1, dtype=torch.bool)).shape
        torch.Size([2, 1, 3])
    """

    def __init__(
        self,
        *,
        lambda1: float = 0.1,
        lambda2: float | None = None,
        method: str = "auto",
        prior_weight: float = 1e-6,
    ) -> None:
        super().__init__()
        if method not in _METHODS:
            raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
        self.lambda1 = float(lambda1)
        self.lambda2 = None if lambda2 is None else float(lambda2)
        self.method = method
        self.prior_weight = float(prior_weight)

    def forward(
        self,
        A: torch.Tensor,
        centers: ArrayIn,
        rays: ArrayIn,
        visible: ArrayIn,
        x_prior: ArrayIn | None = None,
    ) -> torch.Tensor:
        """Solve for X, shape ``(N, J, 3)`` or ``(B, N, J, 3)``; see :func:`solve_structure`."""
        return solve_structure(
            A, centers, rays, visible, lambda1=self.lambda1, lambda2=self.lambda2, method=self.method,
            x_prior=x_prior, prior_weight=self.prior_weight,
        )  # fmt: skip

    def extra_repr(self) -> str:
        """Configuration shown by print(module)."""
        return f"lambda1={self.lambda1}, lambda2={self.lambda2}, method={self.method!r}"
