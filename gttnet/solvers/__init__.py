"""Differentiable solvers: the DLOE X-step (structure from an affinity graph and viewing rays).

The torch X-step (:mod:`~gttnet.solvers.xstep`) is imported on first use of one of its names, so that
``gttnet.solvers.numpy_xstep`` (the classical methods' torch-free X-step) loads without torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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


def __getattr__(name: str) -> Any:
    """The public names of :mod:`gttnet.solvers.xstep`, imported (with torch) when first asked for."""
    if name in __all__:
        return getattr(importlib.import_module("gttnet.solvers.xstep"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
