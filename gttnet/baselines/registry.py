"""Old home of the method registry, kept as a re-export: import from :mod:`gttnet.methods` instead."""

from __future__ import annotations

from gttnet.methods import (
    MethodSpec,
    Reconstruction,
    available_methods,
    check_sequencing,
    method_spec,
    reconstruct,
    register_method,
)

__all__ = [
    "MethodSpec",
    "Reconstruction",
    "available_methods",
    "check_sequencing",
    "method_spec",
    "reconstruct",
    "register_method",
]
