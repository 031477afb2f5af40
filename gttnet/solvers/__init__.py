"""Differentiable solvers: the DLOE X-step (structure from an affinity graph and viewing rays)."""

from __future__ import annotations

from gttnet.solvers.xstep import (
    DLOESolver,
    SingularStructureError,
    laplacians,
    noise_aware_lambda2,
    solve_structure,
    solve_structure_dense,
    structure_energy,
)

__all__ = [
    "DLOESolver",
    "SingularStructureError",
    "laplacians",
    "noise_aware_lambda2",
    "solve_structure",
    "solve_structure_dense",
    "structure_energy",
]
