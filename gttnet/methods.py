"""The reconstruction-method registry: one call signature, sequencing checks and timing for every method.

Every method is a function ``fn(obs: Observations, **options) -> Reconstruction`` registered under a name;
:func:`reconstruct` looks it up, checks the input has the sequencing the method needs, rejects unknown
options, times the call and fills in the recovered order. Ground truth never reaches a method.

This module sits below ``gttnet.baselines`` and ``gttnet.model``: they import it to register, it imports
nothing of theirs at import time.

Adding a method takes one decorator and one line:

1. decorate the function where it lives::

       @register_method("mymethod", requires="none", summary="what it does, in one line")
       def reconstruct_mymethod(obs: Observations, *, iters: int = 10) -> Reconstruction: ...

   Keyword arguments become the method's options (``reconstruct(obs, "mymethod", iters=5)``; recipes'
   ``options:``); an unknown option is a ValueError naming the valid ones.
2. add its name and module to :data:`BUILTIN_METHODS` (a lookup imports only the module of the method it
   names, so a classical method never loads torch; :func:`available_methods` imports them all, and a
   missing module is an ImportError, never a silent skip).
"""

from __future__ import annotations

import importlib
import inspect
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from gttdata.capture.views import SEQUENCING, Observations
from gttnet._builtin_methods import BUILTIN_METHODS
from gttnet.errors import GttNetError, SequencingError

__all__ = [
    "Reconstruction",
    "MethodSpec",
    "register_method",
    "reconstruct",
    "available_methods",
    "BUILTIN_METHODS",
    "method_names",
    "method_spec",
    "check_sequencing",
    "blank_unobserved",
    "assessed",
]

log = logging.getLogger(__name__)

#: A method function: ``fn(obs, **options) -> Reconstruction``.
MethodFn = Callable[..., "Reconstruction"]

_LEVEL = {name: i for i, name in enumerate(SEQUENCING)}  # none < partial < full
_NEEDS_TEXT = {"none": "nothing", "partial": "per-camera stream order", "full": "the global image order"}


@dataclass(frozen=True)
class Reconstruction:
    """The output of a reconstruction method.

    Args:
        points3d: Reconstructed joints in world, metres, shape ``(N, J, 3)``, in the input's image order.
        affinity: Estimated affinity between images, shape ``(N, N)``, or None when the method has none.
        order: Recovered rank of each image in time (0 = first), shape ``(N,)``, or None.
        seconds: Wall-clock time of the method, seconds.
        method: Registered method name.
        sequencing: Sequencing condition of the input (``"none"``, ``"partial"`` or ``"full"``).
        info: Method-specific diagnostics (iterations, chosen hyper-parameters...), JSON-serialisable;
            :func:`reconstruct` adds ``quality``, the self-assessment of :func:`gttnet.quality.assess`.
        uncertainty_mm: Per-point uncertainty, millimetres, shape ``(N, J)``: the bound each joint's 3-D
            error stays below at ``info["quality"]["interval_rate"]`` (None until :func:`reconstruct`
            assesses the reconstruction; NaN where a joint is not reconstructed).
    """

    points3d: np.ndarray
    affinity: np.ndarray | None = None
    order: np.ndarray | None = None
    seconds: float = 0.0
    method: str = ""
    sequencing: str = "none"
    info: dict[str, Any] = field(default_factory=dict, compare=False)
    uncertainty_mm: np.ndarray | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        X = np.asarray(self.points3d, dtype=np.float64)
        if X.ndim != 3 or X.shape[2] != 3:
            raise ValueError(f"Reconstruction.points3d must have shape (N, J, 3), got {X.shape}")
        n = X.shape[0]
        object.__setattr__(self, "points3d", X)
        if self.affinity is not None:
            A = np.asarray(self.affinity, dtype=np.float64)
            if A.shape != (n, n):
                raise ValueError(f"Reconstruction.affinity must have shape ({n}, {n}), got {A.shape}")
            object.__setattr__(self, "affinity", A)
        if self.order is not None:
            o = np.asarray(self.order, dtype=np.int64)
            if o.shape != (n,):
                raise ValueError(f"Reconstruction.order must have shape ({n},), got {o.shape}")
            object.__setattr__(self, "order", o)

    @property
    def n_images(self) -> int:
        """Number of images N."""
        return int(self.points3d.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return int(self.points3d.shape[1])

    @property
    def nan_joints(self) -> np.ndarray:
        """Indices of the joints left NaN in some image (never observed, or too few rays), shape ``(K,)``."""
        return np.flatnonzero(~np.isfinite(self.points3d).all(axis=(0, 2)))


@dataclass(frozen=True)
class MethodSpec:
    """A registered method.

    Args:
        name: Registry name.
        requires: The least sequencing condition the method needs (``"none"``, ``"partial"`` or ``"full"``).
        fn: ``fn(obs, **options) -> Reconstruction``; ``seconds``, ``method`` and ``sequencing`` are
            filled in by :func:`reconstruct`.
        summary: One line describing the method.
        needs: What the method needs, in words, for error messages (default from ``requires``).
    """

    name: str
    requires: str
    fn: Callable[..., Reconstruction]
    summary: str = ""
    needs: str = ""


_REGISTRY: dict[str, MethodSpec] = {}
_LOADED = False


def register_method(
    name: str, *, requires: str = "none", summary: str = "", needs: str = ""
) -> Callable[[MethodFn], MethodFn]:
    """Decorator registering ``fn(obs: Observations, **options) -> Reconstruction`` under ``name``.

    Args:
        name: Method name used by :func:`reconstruct` and ``gttnet reconstruct --method``.
        requires: Least sequencing condition the method needs: ``"none"``, ``"partial"`` or ``"full"``.
        summary: One line for listings (defaults to the function docstring's first line).
        needs: What the method needs, in words, for the SequencingError message, e.g.
            ``"timestamps"``; the condition name is appended.

    Returns:
        The decorator; it returns ``fn`` unchanged.
    """
    if requires not in _LEVEL:
        raise ValueError(f"register_method({name!r}): requires must be one of {SEQUENCING}, got {requires!r}")

    def deco(fn: MethodFn) -> MethodFn:
        if name in _REGISTRY and _REGISTRY[name].fn is not fn:
            log.warning("method %r re-registered by %s.%s", name, fn.__module__, fn.__qualname__)
        doc = summary or (inspect.getdoc(fn) or "").split("\n")[0]
        _REGISTRY[name] = MethodSpec(name=name, requires=requires, fn=fn, summary=doc, needs=needs)
        return fn

    return deco


def _load_builtin_methods() -> None:
    """Import the modules whose ``@register_method`` decorators define the built-in methods (once).

    The imports are explicit and function-local: those modules import this one to register, so importing
    them here at module level would be a cycle. Add a new method's module here (one line).
    """
    global _LOADED
    if _LOADED:
        return
    for module in sorted(set(BUILTIN_METHODS.values())):
        importlib.import_module(module)
    _LOADED = True


def method_names() -> tuple[str, ...]:
    """Names of the built-in and registered methods, sorted, without importing any method's module."""
    return tuple(sorted(set(BUILTIN_METHODS) | set(_REGISTRY)))


def available_methods() -> dict[str, str]:
    """Registered method names mapped to the least sequencing condition each needs."""
    _load_builtin_methods()
    return {name: spec.requires for name, spec in sorted(_REGISTRY.items())}


def method_spec(name: str) -> MethodSpec:
    """The registry entry of a method.

    Raises:
        ValueError: For an unknown name.
    """
    if name not in _REGISTRY and name in BUILTIN_METHODS:
        importlib.import_module(BUILTIN_METHODS[name])  # this method's module only (see BUILTIN_METHODS)
    if name not in _REGISTRY:
        _load_builtin_methods()
    if name in _REGISTRY:
        return _REGISTRY[name]
    raise ValueError(f"unknown method {name!r}; expected one of {', '.join(sorted(_REGISTRY))}")


def check_sequencing(obs: Observations, spec: MethodSpec) -> None:
    """Raise SequencingError when ``obs`` lacks the sequencing ``spec`` needs."""
    if _LEVEL[obs.sequencing] < _LEVEL[spec.requires]:
        needs = spec.needs or _NEEDS_TEXT[spec.requires]
        cond = "'full'" if spec.requires == "full" else "'partial' or 'full'"
        raise SequencingError(
            f"method {spec.name!r} needs {needs} (sequencing {cond}); input has sequencing {obs.sequencing!r}"
        )


def _check_options(spec: MethodSpec, options: dict[str, Any]) -> None:
    params = inspect.signature(spec.fn).parameters
    if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values()):
        return
    known = [p for p in list(params)[1:]]
    bad = sorted(set(options) - set(known))
    if bad:
        raise ValueError(
            f"method {spec.name!r} has no option {bad[0]!r}; options: {', '.join(known) or 'none'}"
        )


def reconstruct(obs: Observations, method: str, **options: Any) -> Reconstruction:
    """Reconstruct 3D joints from observations with a registered method.

    Ground truth never reaches a method: this takes only the :class:`Observations`.

    Args:
        obs: Solver inputs for one sequencing condition.
        method: Registered method name (see :func:`available_methods`).
        **options: Method options (keyword arguments of the method function).

    Returns:
        The reconstruction, timed, with ``order`` recovered by :func:`spectral_order` when the method
        returns an affinity but no order.

    Raises:
        SequencingError: If the method needs more sequencing than ``obs`` has.
        GttNetError: If no image observes any joint. Joints that no image observes are NaN in the result
            (``info["unobserved_joints"]`` names them).
        ModelError: For ``"gttnet"`` without a trained model (raised by the method).
        ValueError: For an unknown method or option.
    """
    if not isinstance(obs, Observations):
        raise TypeError(f"reconstruct: obs must be Observations, got {type(obs).__name__}")
    spec = method_spec(method)
    check_sequencing(obs, spec)
    _check_options(spec, options)
    if not np.asarray(obs.visible, dtype=bool).any():
        raise GttNetError(
            f"reconstruct: no joint of the {obs.n_joints}-joint skeleton {obs.skeleton.name!r} is observed "
            f"in any of the {obs.n_images} images"
        )
    t0 = time.perf_counter()
    rec = spec.fn(obs, **options)
    order = rec.order
    if order is None and rec.affinity is not None:
        from gttnet.geometry.ordering import spectral_order

        order = spectral_order(rec.affinity)
    seconds = time.perf_counter() - t0
    if rec.points3d.shape != (obs.n_images, obs.n_joints, 3):
        raise RuntimeError(
            f"method {method!r} returned points3d of shape {rec.points3d.shape}, "
            f"expected {(obs.n_images, obs.n_joints, 3)}"
        )
    log.info("%s (%s): %d images in %.2f s", method, obs.sequencing, obs.n_images, seconds)
    rec = replace(rec, order=order, seconds=seconds, method=method, sequencing=obs.sequencing)
    return assessed(blank_unobserved(rec, obs), obs)


def assessed(rec: Reconstruction, obs: Observations) -> Reconstruction:
    """``rec`` with its self-assessment: ``info["quality"]`` and ``uncertainty_mm`` (:mod:`gttnet.quality`).

    Computed from ``obs`` and ``rec`` only (no ground truth); a method that assessed itself (``auto``
    passes on its chosen candidate's) keeps its own.
    """
    from gttnet.quality import assess

    if "quality" in rec.info and rec.uncertainty_mm is not None:
        return rec
    quality, unc = assess(obs, rec)
    return replace(rec, info={**rec.info, "quality": quality}, uncertainty_mm=unc)


def blank_unobserved(rec: Reconstruction, obs: Observations) -> Reconstruction:
    """NaN for the joints no image of ``obs`` observes (a method's value for them would be made up).

    Warns naming them and lists them in ``info["unobserved_joints"]``; ``rec`` unchanged when every joint
    is observed somewhere.
    """
    unseen = ~np.asarray(obs.visible, dtype=bool).any(axis=0)
    if not unseen.any():
        return rec
    names = [obs.skeleton.joint_names[j] for j in np.flatnonzero(unseen)]
    log.warning(
        "%s: %s %s missing in every image: 3D left NaN",
        rec.method,
        "joints" if len(names) > 1 else "joint",
        ", ".join(names),
    )
    X = rec.points3d.copy()
    X[:, unseen] = np.nan
    return replace(rec, points3d=X, info={**rec.info, "unobserved_joints": names})
