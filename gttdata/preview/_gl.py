"""Offscreen OpenGL backend selection for pyrender (EGL first, OSMesa as fallback), one renderer per process."""

from __future__ import annotations

import atexit
import importlib
import importlib.util
import logging
import os
import sys
from types import ModuleType
from typing import Any

from gttdata.errors import PreviewDependencyError, RendererUnavailableError

__all__ = [
    "PreviewDependencyError",
    "RendererUnavailableError",
    "gl_backend",
    "offscreen_renderer",
    "require",
]

_log = logging.getLogger(__name__)

_INSTALL_HINT = "install the preview extra: pip install 'gtt[preview]'"


# The process-wide renderer: (pyrender module, OffscreenRenderer, backend name), or the error that
# prevented it. Creating a GL context costs ~0.4 s on llvmpipe, so it is made once and reused.
_STATE: dict[str, Any] = {}  # pyrender module, its renderer (both untyped), backend name, error


def require(name: str) -> ModuleType:
    """Import an optional preview dependency, or raise a one-line error saying how to install it.

    Args:
        name: Module name, e.g. ``"matplotlib"`` or ``"trimesh"``.

    Raises:
        PreviewDependencyError: The module is not installed.
    """
    if importlib.util.find_spec(name) is None:
        raise PreviewDependencyError(f"{name} is not installed; {_INSTALL_HINT}")
    return importlib.import_module(name)


def _purge_gl_modules() -> None:
    """Forget OpenGL and pyrender so the next import picks up a new PYOPENGL_PLATFORM."""
    for mod in [m for m in sys.modules if m.split(".")[0] in ("OpenGL", "pyrender")]:
        del sys.modules[mod]


def _try_backend(platform: str, *, retry: bool) -> tuple[ModuleType, object]:
    """Import pyrender on ``platform`` and create a small offscreen renderer (raises on failure).

    PyOpenGL binds its platform at first import, so a retry on another backend re-imports it.
    """
    os.environ["PYOPENGL_PLATFORM"] = platform
    if retry:
        _purge_gl_modules()
    pyrender = importlib.import_module("pyrender")
    renderer = pyrender.OffscreenRenderer(8, 8)
    return pyrender, renderer


def _create() -> None:
    require("trimesh")
    require("pyrender")
    user = os.environ.get("PYOPENGL_PLATFORM")
    candidates = [user] if user else ["egl", "osmesa"]
    errors = []
    for k, platform in enumerate(candidates):
        try:
            pyrender, renderer = _try_backend(platform, retry=k > 0)
        # PyOpenGL and the platform libraries fail with many exception types (ImportError, OSError,
        # RuntimeError, AttributeError, GLError...); any of them means "this backend does not work".
        except Exception as exc:  # noqa: BLE001
            msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
            errors.append(f"{platform}: {msg}")
            _log.info("offscreen GL backend %s failed: %s", platform, msg)
            continue
        _STATE.update(pyrender=pyrender, renderer=renderer, backend=platform)
        atexit.register(_release)
        _log.info("offscreen GL backend: %s", platform)
        return
    if not user:
        os.environ.pop("PYOPENGL_PLATFORM", None)
    hint = (
        "PYOPENGL_PLATFORM is set by you; unset it to let gttdata try egl then osmesa"
        if user
        else "install Mesa (scripts/gl_deps.sh: libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1, or libosmesa6 "
        "with PyOpenGL >= 3.1.5 for osmesa) or render without 3D (--no-3d)"
    )
    _STATE["error"] = f"no offscreen OpenGL backend works ({'; '.join(errors)}); {hint}"


def _release() -> None:
    renderer = _STATE.pop("renderer", None)
    if renderer is not None:
        try:
            renderer.delete()
        except Exception:  # noqa: BLE001 - interpreter shutdown: the context may already be gone
            pass


def offscreen_renderer(width: int, height: int) -> tuple[ModuleType, Any]:
    """The process-wide pyrender module and OffscreenRenderer, resized to ``width`` x ``height``.

    The first call picks the backend: the user's ``PYOPENGL_PLATFORM`` when set, else EGL, then OSMesa.

    Args:
        width: Viewport width in pixels.
        height: Viewport height in pixels.

    Returns:
        ``(pyrender, renderer)``.

    Raises:
        PreviewDependencyError: trimesh or pyrender is not installed.
        RendererUnavailableError: No backend can create a context (the message lists each one's error).
    """
    if "renderer" not in _STATE and "error" not in _STATE:
        _create()
    if "error" in _STATE:
        raise RendererUnavailableError(str(_STATE["error"]))
    renderer = _STATE["renderer"]
    if (renderer.viewport_width, renderer.viewport_height) != (int(width), int(height)):
        renderer.viewport_width = int(width)
        renderer.viewport_height = int(height)
    return _STATE["pyrender"], renderer


def gl_backend() -> str | None:
    """Name of the working backend (``"egl"``/``"osmesa"``), or None when none works; never raises."""
    try:
        offscreen_renderer(8, 8)
    except (RendererUnavailableError, PreviewDependencyError):
        return None
    return str(_STATE["backend"])
