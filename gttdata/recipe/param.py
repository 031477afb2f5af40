"""Recipe parameters that hold either a fixed value or a distribution to draw from."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Param", "PARAM_KINDS"]

#: YAML spellings of a parameter: a number, ``{uniform: [a, b]}``, ``{choice: [...]}``,
#: ``{normal: [mu, sigma]}``, or (where a field allows it) a plain list: one value per camera.
PARAM_KINDS: tuple[str, ...] = ("value", "uniform", "choice", "normal", "list")


@dataclass(frozen=True)
class Param:
    """A number, or a distribution over numbers, as written in a recipe.

    Draws are clipped to the field's range ``[lo, hi]`` (a normal can leave it) and rounded when the
    field is an integer; ``uniform`` over an integer field draws from ``{a, ..., b}`` inclusive.

    Args:
        kind: One of :data:`PARAM_KINDS`.
        args: ``(v,)`` for value; ``(a, b)`` for uniform; ``(mu, sigma)`` for normal; the options for
            choice; the per-camera values for list.
        integer: Whether draws are integers.
        lo: Smallest allowed draw (None: unbounded).
        hi: Largest allowed draw (None: unbounded).

    Example:
        >>> p = Param("uniform", (3.0, 6.0), integer=True)
        >>> int(p.draw(np.random.default_rng(0))) in {3, 4, 5, 6}
        True
    """

    kind: str
    args: tuple[float, ...]
    integer: bool = field(default=False, compare=False)
    lo: float | None = field(default=None, compare=False)
    hi: float | None = field(default=None, compare=False)

    @classmethod
    def of(cls, value: float, **kw) -> Param:
        """A fixed value."""
        return cls("value", (value,), **kw)

    @property
    def is_fixed(self) -> bool:
        """True when every draw gives the same value."""
        return self.kind == "value" or (self.kind in ("uniform", "choice") and len(set(self.args)) == 1)

    def _finish(self, x: np.ndarray) -> np.ndarray:
        lo = -np.inf if self.lo is None else self.lo
        hi = np.inf if self.hi is None else self.hi
        x = np.clip(x, lo, hi)
        return np.rint(x).astype(np.int64) if self.integer else x.astype(np.float64)

    def draw(self, rng: np.random.Generator, size: int | None = None) -> np.ndarray:
        """Draw value(s).

        Args:
            rng: Random generator.
            size: Number of draws (e.g. one per camera), or None for a scalar.

        Returns:
            A 0-d array (``size`` None) or shape ``(size,)``; int64 for integer fields, else float64.
            A ``list`` parameter gives element ``v % len`` as draw ``v`` (and its first element as scalar).
        """
        n = 1 if size is None else size
        a = self.args
        if self.kind == "value":
            x = np.full(n, a[0], dtype=np.float64)
        elif self.kind == "list":
            x = np.array([a[v % len(a)] for v in range(n)], dtype=np.float64)
        elif self.kind == "choice":
            x = np.asarray(a, dtype=np.float64)[rng.integers(0, len(a), size=n)]
        elif self.kind == "uniform" and self.integer:
            x = rng.integers(int(np.ceil(a[0])), int(np.floor(a[1])) + 1, size=n).astype(np.float64)
        elif self.kind == "uniform":
            x = rng.uniform(a[0], a[1], size=n)
        elif self.kind == "normal":
            x = rng.normal(a[0], a[1], size=n)
        else:
            raise ValueError(f"Param.kind must be one of {PARAM_KINDS}, got {self.kind!r}")
        x = self._finish(x)
        return x[0] if size is None else x

    def to_yaml(self) -> object:
        """The recipe spelling: a number, a list, or a one-key mapping."""
        if self.kind == "value":
            return self.args[0]
        if self.kind == "list":
            return list(self.args)
        return {self.kind: list(self.args)}
