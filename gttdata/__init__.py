"""gttdata: simulated unsynchronized multi-camera captures from mocap, as sharded HDF5.

This package never imports torch or gttnet. The names below are loaded on first access (PEP 562), so
``import gttdata`` (and the ``gttdata`` CLI's ``--help``) does not pay for numpy, scipy, OpenCV or h5py.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY = {
    "Camera": "gttdata.cameras",
    "CameraRig": "gttdata.cameras",
    "look_at": "gttdata.cameras",
    "ring_rig": "gttdata.cameras",
    "CaptureSample": "gttdata.capture.sample",
    "SEQUENCING": "gttdata.capture.views",
    "GroundTruth": "gttdata.capture.views",
    "Observations": "gttdata.capture.views",
    "make_view": "gttdata.capture.views",
    "GttDataError": "gttdata.errors",
    "Motion": "gttdata.mocap.motion",
    "Skeleton": "gttdata.skeleton",
    "cmu31": "gttdata.skeleton",
    "available_skeletons": "gttdata.skeletons",
    "derive_from_cmu31": "gttdata.skeletons",
    "get_skeleton": "gttdata.skeletons",
}

__all__ = [
    "__version__",
    "Camera",
    "CameraRig",
    "CaptureSample",
    "GroundTruth",
    "GttDataError",
    "Motion",
    "Observations",
    "SEQUENCING",
    "Skeleton",
    "available_skeletons",
    "cmu31",
    "derive_from_cmu31",
    "get_skeleton",
    "look_at",
    "make_view",
    "ring_rig",
]

if TYPE_CHECKING:  # pragma: no cover - static analysers see the eager imports
    from gttdata.cameras import Camera, CameraRig, look_at, ring_rig
    from gttdata.capture.sample import CaptureSample
    from gttdata.capture.views import SEQUENCING, GroundTruth, Observations, make_view
    from gttdata.errors import GttDataError
    from gttdata.mocap.motion import Motion
    from gttdata.skeleton import Skeleton, cmu31
    from gttdata.skeletons import available_skeletons, derive_from_cmu31, get_skeleton


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'gttdata' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
