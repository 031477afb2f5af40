"""What the benchmark tables share: the cell format (a median with its spread) and which captures they score."""

from __future__ import annotations

import statistics

__all__ = ["fmt", "spaced"]


def fmt(xs: list[float], spec: str = ".2f") -> str:
    """``median (min..max)`` of ``xs``, each formatted with ``spec``."""
    return f"{statistics.median(xs):{spec}} ({min(xs):{spec}}..{max(xs):{spec}})"


def spaced(total: int, n: int) -> list[int]:
    """Indices of at most ``n`` captures spread evenly over a split of ``total``: every ``total // n``-th."""
    n = min(n, total)
    return [i * max(1, total // n) for i in range(n)]
