"""The cell format the benchmark tables share: a median with its spread over sequences and runs."""

from __future__ import annotations

import statistics

__all__ = ["fmt"]


def fmt(xs: list[float], spec: str = ".2f") -> str:
    """``median (min..max)`` of ``xs``, each formatted with ``spec``."""
    return f"{statistics.median(xs):{spec}} ({min(xs):{spec}}..{max(xs):{spec}})"
