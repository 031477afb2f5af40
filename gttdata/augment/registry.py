"""Name registry of augmentations, with validation of their parameters against their signatures."""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "AUGMENT_LEVELS",
    "Augmentation",
    "available_augmentations",
    "fires",
    "get_augmentation",
    "register_augmentation",
    "validate_augmentation",
]

#: ``capture``: ``(sample, rng, **params) -> CaptureSample`` (one stored variant each);
#: ``motion``: ``(motion, rng, **params) -> Motion`` (applied before simulation).
AUGMENT_LEVELS: tuple[str, ...] = ("capture", "motion")

_REGISTRY: dict[str, Augmentation] = {}


def fires(rng: np.random.Generator, prob: float) -> bool:
    """Whether an augmentation applied with probability ``prob`` fires this time.

    Draws one number from ``rng`` only when ``prob > 0``, so recipes that leave a control at 0 keep
    their random streams (and shards) unchanged.

    Args:
        rng: Random generator.
        prob: Probability of firing, in [0, 1].

    Returns:
        True with probability ``prob``.
    """
    return not (prob <= 0 or rng.random() >= prob)


@dataclass(frozen=True)
class Augmentation:
    """A registered augmentation.

    Args:
        name: Registered name.
        level: One of :data:`AUGMENT_LEVELS`.
        fn: The transform; its keyword-only parameters (with defaults) are its recipe ``params``.
        choices: Allowed values of string parameters, by parameter name.
        ranges: Inclusive ``(lo, hi)`` bounds of numeric parameters, by parameter name.
    """

    name: str
    level: str
    fn: Callable
    choices: dict[str, tuple] = field(default_factory=dict)
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)

    def defaults(self) -> dict:
        """Keyword-only parameters and their defaults."""
        sig = inspect.signature(self.fn)
        return {n: p.default for n, p in sig.parameters.items() if p.kind is inspect.Parameter.KEYWORD_ONLY}


def register_augmentation(
    name: str, *, level: str, choices: dict | None = None, ranges: dict | None = None
) -> Callable[[Callable], Callable]:
    """Decorator registering an augmentation under ``name``.

    Args:
        name: Registered name used in recipes.
        level: ``capture`` or ``motion``.
        choices: Allowed values of string parameters.
        ranges: Inclusive numeric bounds of parameters.
    """
    if level not in AUGMENT_LEVELS:
        raise ValueError(f"level must be one of {AUGMENT_LEVELS}, got {level!r}")

    def decorate(fn: Callable) -> Callable:
        _REGISTRY[name] = Augmentation(name, level, fn, dict(choices or {}), dict(ranges or {}))
        return fn

    return decorate


def available_augmentations(level: str | None = None) -> tuple[str, ...]:
    """Registered names (of one level, or all), sorted."""
    return tuple(sorted(n for n, a in _REGISTRY.items() if level is None or a.level == level))


def get_augmentation(name: str, *, level: str | None = None) -> Augmentation:
    """The augmentation registered as ``name``; KeyError naming the known ones otherwise."""
    aug = _REGISTRY.get(name)
    if aug is None or (level is not None and aug.level != level):
        known = ", ".join(available_augmentations(level))
        raise KeyError(f"augmentation {name!r} is not registered (level {level}); known: {known}")
    return aug


def _check_value(aug: Augmentation, key: str, value: object, default: object) -> str | None:
    """Problem text (``params.key: expected ..., found ...``) or None."""
    where = f"params.{key}"
    if isinstance(default, bool):
        ok = isinstance(value, bool)
        expected = "true or false"
    elif isinstance(default, int | float):
        num = value if isinstance(value, int | float) and not isinstance(value, bool) else None
        lo, hi = aug.ranges.get(key, (None, None))
        ok = num is not None and (lo is None or num >= lo) and (hi is None or num <= hi)
        expected = "a number" + (f" in [{lo}, {hi}]" if key in aug.ranges else "")
    elif isinstance(default, str):
        allowed = aug.choices.get(key)
        ok = isinstance(value, str) and (allowed is None or value in allowed)
        expected = "one of " + ", ".join(repr(c) for c in allowed) if allowed else "a string"
    else:
        return None
    return None if ok else f"{where}: expected {expected}, found {value!r}"


def validate_augmentation(name: str, params: dict, *, level: str) -> str | None:
    """Check a recipe entry without running it.

    Returns:
        None when valid, else the problem as ``"name: expected ..., found ..."`` or
        ``"params.key: ..."`` (the caller prefixes file and list position).
    """
    if name not in available_augmentations(level):
        return f"name: expected one of {', '.join(available_augmentations(level))}, found {name!r}"
    aug = _REGISTRY[name]
    defaults = aug.defaults()
    for key, value in params.items():
        if key not in defaults:
            return f"params.{key}: unknown parameter of {name!r} (expected one of: {', '.join(defaults)})"
        problem = _check_value(aug, key, value, defaults[key])
        if problem:
            return problem
    return None
