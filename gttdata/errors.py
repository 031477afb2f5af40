"""Exception types raised by gttdata; the CLI turns each into one readable line."""

from __future__ import annotations

__all__ = [
    "GttDataError",
    "MotionFormatError",
    "RecipeError",
    "RigError",
    "ShardFormatError",
    "ManifestError",
    "OutputError",
    "PreviewDependencyError",
    "RendererUnavailableError",
    "KeypointFormatError",
    "CalibrationError",
]


class GttDataError(Exception):
    """Base class of every error gttdata raises on bad input or bad files."""


class MotionFormatError(GttDataError):
    """A motion file is malformed (names file, line or field, expected and found)."""


class RecipeError(GttDataError):
    """A recipe is invalid (names the key, the expected type or range, and the value found)."""


class RigError(GttDataError):
    """A camera or rig is invalid (singular K, non-orthonormal rotation, zero image size...)."""


class ShardFormatError(GttDataError):
    """A shard is corrupt, truncated or of an unknown schema version."""


class ManifestError(GttDataError):
    """A manifest is missing, malformed, or disagrees with the shards on disk."""


class OutputError(GttDataError):
    """An output cannot be written.

    An output cannot be written: full disk, read-only file system, an existing output without
    ``--resume``/``--overwrite``, or a folder another process is writing (names the path).
    """


class PreviewDependencyError(GttDataError):
    """An optional preview dependency (matplotlib, trimesh, pyrender) is not installed."""


class RendererUnavailableError(GttDataError):
    """No offscreen OpenGL backend (EGL or OSMesa) can create a rendering context."""


class KeypointFormatError(GttDataError):
    """A 2-D detector output (OpenPose, DeepLabCut, SLEAP, COCO/MMPose) is malformed or inconsistent."""


class CalibrationError(RigError):
    """A calibration file is malformed, in unknown units, or disagrees with the keypoint sources."""
