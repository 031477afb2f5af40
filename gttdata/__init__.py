"""gttdata: simulated unsynchronized multi-camera captures from mocap, as sharded HDF5.

This package never imports torch or gttnet.
"""

from __future__ import annotations

from gttdata.cameras import Camera, CameraRig, look_at, ring_rig
from gttdata.capture.sample import CaptureSample
from gttdata.capture.views import SEQUENCING, GroundTruth, Observations, make_view
from gttdata.errors import GttDataError
from gttdata.mocap.motion import Motion
from gttdata.skeleton import Skeleton, cmu31
from gttdata.skeletons import available_skeletons, derive_from_cmu31, get_skeleton

__version__ = "0.1.0"

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
