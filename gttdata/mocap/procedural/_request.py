"""Argument checks and the size draw shared by the hand and quadruped generators."""

from __future__ import annotations

import numpy as np

__all__ = ["check_request", "draw_scale"]


def check_request(
    what: str, kind: str, kinds: tuple[str, ...], seed: int, duration_s: float, fps_hz: float
) -> None:
    """Raise on an unknown kind, a negative seed, a non-positive duration or a frame rate under 10 Hz.

    Args:
        what: The generator's subject in the message (``"hand"``, ``"quadruped"``).
        kind: Requested motion kind.
        kinds: The kinds the generator knows.
        seed: Seed, must be >= 0.
        duration_s: Length in seconds, must be > 0.
        fps_hz: Frame rate, Hz, must be >= 10.

    Raises:
        ValueError: One line naming the bad argument, what was expected and what was given.
    """
    if kind not in kinds:
        raise ValueError(f"unknown {what} motion kind {kind!r}; expected one of {', '.join(kinds)}")
    if seed < 0 or duration_s <= 0 or fps_hz < 10:
        raise ValueError(f"need seed >= 0, duration_s > 0, fps_hz >= 10; got {seed}, {duration_s}, {fps_hz}")


def draw_scale(
    rng: np.random.Generator,
    given: float | None,
    name: str,
    draw: tuple[float, float],
    allowed: tuple[float, float],
) -> float:
    """The subject's size factor: ``given``, or drawn uniformly in ``draw`` when None; checked against ``allowed``.

    Args:
        rng: Random generator (drawn from only when ``given`` is None).
        given: Requested size factor, or None.
        name: The argument's name in the message.
        draw: Range of the draw, ``(low, high)``.
        allowed: Accepted range, ``(low, high)``, inclusive.

    Returns:
        The size factor.

    Raises:
        ValueError: The factor lies outside ``allowed``.
    """
    s = float(rng.uniform(*draw) if given is None else given)
    if not allowed[0] <= s <= allowed[1]:
        raise ValueError(f"{name} must be in [{allowed[0]:g}, {allowed[1]:g}], got {s}")
    return s
