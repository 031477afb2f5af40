"""Exception types raised by gttnet; the CLI turns each into one readable line.

``SequencingError`` is gttdata's (views raise it too), re-exported here.
"""

from __future__ import annotations

from gttdata.errors import GttDataError, SequencingError

__all__ = ["GttNetError", "ImportFormatError", "SequencingError", "ModelError", "SingularStructureError"]


class GttNetError(GttDataError):
    """Base class of gttnet's input errors."""


class ImportFormatError(GttNetError):
    """A reconstruction input file is malformed (names file, field, expected and found)."""


class ModelError(GttNetError):
    """A model file is missing or incompatible."""


class SingularStructureError(GttNetError):
    """The X-step has no unique solution (a joint unobserved in a connected part of the graph)."""
