"""Classical reconstruction methods, each registered in :mod:`gttnet.methods` by its module.

``pseudo`` (pseudo-triangulation, :mod:`~gttnet.baselines.pseudo`), ``dloe`` (DLOE alternating
optimisation, :mod:`~gttnet.baselines.dloe`), ``dct`` (trajectory basis; needs timestamps,
:mod:`~gttnet.baselines.trajectory_basis`) and ``hpf`` (high-pass filter prior; needs the global order,
:mod:`~gttnet.baselines.highpass`). Call them through :func:`gttnet.methods.reconstruct`.
"""

from gttnet.methods import Reconstruction, available_methods, reconstruct, register_method

__all__ = ["Reconstruction", "available_methods", "reconstruct", "register_method"]  # kept for old imports
