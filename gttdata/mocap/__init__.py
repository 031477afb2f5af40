"""Registry of motion-file loaders, chosen by file suffix or by explicit format name."""

from __future__ import annotations

import importlib
import logging
from collections.abc import Callable
from pathlib import Path

from gttdata.errors import MotionFormatError
from gttdata.mocap.motion import Motion

__all__ = ["Motion", "available_formats", "format_for_path", "load_motion", "register_loader"]

_log = logging.getLogger(__name__)

#: Built-in loader modules, imported on first use so importing this package stays cheap.
_BUILTIN_MODULES: tuple[str, ...] = (
    "gttdata.mocap.bvh",
    "gttdata.mocap.asfamc",
    "gttdata.mocap.c3d",
    "gttdata.mocap.arrays",
)

_LOADERS: dict[str, Callable[..., Motion]] = {}
_SUFFIXES: dict[str, str] = {}
_builtins_loaded = False


def register_loader(fmt: str, suffixes: tuple[str, ...] | list[str] = ()) -> Callable:
    """Decorator registering ``loader(path, **options) -> Motion`` under ``fmt``.

    Args:
        fmt: Format name, e.g. ``"bvh"``; lower case.
        suffixes: File suffixes (with the dot, lower case, e.g. ``(".bvh",)``) that select this
            format when ``load_motion(..., fmt="auto")``.

    Example:
        >>> @register_loader("doctest-fmt", suffixes=(".dtf",))
        ... def _load(path, **options):
        ...     raise NotImplementedError
        >>> "doctest-fmt" in available_formats()
        True
    """
    fmt = fmt.lower()

    def decorate(fn: Callable[..., Motion]) -> Callable[..., Motion]:
        if fmt in _LOADERS and _LOADERS[fmt] is not fn:
            _log.debug("loader for %r replaced by %s", fmt, fn.__qualname__)
        _LOADERS[fmt] = fn
        for s in suffixes:
            _SUFFIXES[s.lower()] = fmt
        return fn

    return decorate


def _load_builtins() -> None:
    global _builtins_loaded
    if not _builtins_loaded:
        for mod in _BUILTIN_MODULES:
            importlib.import_module(mod)
        _builtins_loaded = True


def available_formats() -> tuple[str, ...]:
    """Names of every registered format, sorted."""
    _load_builtins()
    return tuple(sorted(_LOADERS))


def format_for_path(path: str | Path) -> str:
    """Format name chosen for ``path`` by its suffix (the longest registered suffix wins).

    Raises:
        MotionFormatError: No registered suffix matches.
    """
    _load_builtins()
    name = Path(path).name.lower()
    for suffix in sorted(_SUFFIXES, key=len, reverse=True):
        if name.endswith(suffix):
            return _SUFFIXES[suffix]
    raise MotionFormatError(
        f"{path}: unknown motion file suffix; expected one of {', '.join(sorted(_SUFFIXES))} "
        f"or an explicit format ({', '.join(sorted(_LOADERS))})"
    )


def load_motion(path: str | Path, fmt: str = "auto", **options) -> Motion:
    """Load a motion file as a :class:`Motion` in metres, world z-up.

    Args:
        path: Motion file.
        fmt: A registered format name, or ``"auto"`` to choose by suffix.
        **options: Passed to the loader (e.g. ``scale`` for BVH, ``asf_path`` for AMC).

    Raises:
        MotionFormatError: Unknown format, or a malformed file (one line naming file and field).
        FileNotFoundError: ``path`` does not exist.
    """
    _load_builtins()
    path = Path(path)
    name = format_for_path(path) if fmt == "auto" else fmt.lower()
    if name not in _LOADERS:
        raise MotionFormatError(
            f"{path}: unknown motion format {fmt!r}; expected one of {', '.join(sorted(_LOADERS))}"
        )
    if not path.is_file():
        raise FileNotFoundError(2, "motion file not found", str(path))
    _log.debug("loading %s as %s", path, name)
    return _LOADERS[name](path, **options)
