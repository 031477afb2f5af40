"""Reconstruction methods behind one interface: ``reconstruct(obs, method)`` over a registry of methods.

Built-in methods (registered when first looked up): ``pseudo`` (pseudo-triangulation), ``dloe``
(DLOE alternating optimisation), ``dct`` (trajectory basis; needs timestamps) and ``hpf`` (high-pass
filter prior; needs the global order). ``gttnet`` is registered by ``gttnet.model.inference``.
"""

from __future__ import annotations

from gttnet.baselines.registry import (
    MethodSpec,
    Reconstruction,
    available_methods,
    method_spec,
    reconstruct,
    register_method,
)

__all__ = [
    "MethodSpec",
    "Reconstruction",
    "available_methods",
    "method_spec",
    "reconstruct",
    "register_method",
]
