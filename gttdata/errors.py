"""Exception types raised by gttdata; the CLI turns each into one readable line."""

from __future__ import annotations

import functools

import click

__all__ = [
    "friendly_errors",
    "GttDataError",
    "MotionFormatError",
    "RecipeError",
    "RigError",
    "SequencingError",
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


class SequencingError(GttDataError):
    """A view or method needs sequencing information (stream order, global order) the input lacks."""


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


class NoDetectionsError(KeypointFormatError):
    """A keypoint source that holds no detection at all (a camera that never saw anyone)."""


class CalibrationError(RigError):
    """A calibration file is malformed, in unknown units, or disagrees with the keypoint sources."""


def _out_of_memory(detail: str) -> str:
    """The one line for a run that ran out of memory (``detail``: the allocator's own words, if any)."""
    what = f" ({detail.strip()})" if detail.strip() else ""
    return (
        f"out of memory{what}: the machine (or its memory limit) cannot hold this run; "
        "split the input or raise the limit"
    )


def friendly_errors(fn):
    """Decorator: turn library errors (and common OS errors) into one readable ClickException line."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except GttDataError as exc:
            raise click.ClickException(str(exc)) from exc
        except (FileNotFoundError, PermissionError, IsADirectoryError) as exc:
            raise click.ClickException(f"{exc.filename}: {exc.strerror}") from exc
        except OSError as exc:  # ENOSPC, EROFS...: one line naming the path
            from gttdata.fileio import describe_os_error  # fileio imports this module

            reason = describe_os_error(exc)
            raise click.ClickException(f"{exc.filename}: {reason}" if exc.filename else reason) from exc
        except MemoryError as exc:  # numpy's _ArrayMemoryError too: one line, never a traceback
            raise click.ClickException(_out_of_memory(str(exc))) from exc
        except RuntimeError as exc:  # torch's CPU allocator and CUDA report running out as a RuntimeError
            if "can't allocate memory" not in str(exc) and "out of memory" not in str(exc).lower():
                raise
            raise click.ClickException(_out_of_memory(str(exc).splitlines()[0])) from exc

    return wrapper
