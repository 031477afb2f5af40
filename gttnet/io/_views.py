"""Captures imported from other tools' files, in the shape :func:`gttdata.capture.views.make_view` takes."""

from __future__ import annotations

import functools
import warnings
from dataclasses import dataclass

import numpy as np

from gttdata.capture.sample import temporal_affinity
from gttdata.skeleton import Skeleton

__all__ = ["UNITS", "ImportedCapture", "resolve_units"]

#: Length units accepted by the importers, in metres.
UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "inch": 0.0254}


def resolve_units(path: object, layout: str, given: str | None, recorded: str | None = None) -> str:
    """The length unit of a foreign file: what it records, else ``given``, else metres with a warning.

    Args:
        path: The file (named in messages).
        layout: Its layout's name (``gttnet-json``, ``dloe-mat``), for the warning.
        given: The caller's ``--units`` (None: not given).
        recorded: The unit the file records (None: it records none; the authors' files never do).

    Returns:
        A key of :data:`UNITS`.

    Raises:
        ValueError: ``given`` or ``recorded`` is no key of :data:`UNITS`, or the two disagree.

    Warns:
        UserWarning: Neither is known, so metres are assumed (one line naming the file and the way out).
    """
    for what, unit in (("--units", given), ("the file's units", recorded)):
        if unit is not None and (not isinstance(unit, str) or unit not in UNITS):
            raise ValueError(f"{path}: {what}: expected one of {', '.join(UNITS)}, found {unit!r}")
    if recorded is not None:
        if given is not None and given != recorded:
            raise ValueError(
                f"{path}: the file records units {recorded!r}, --units says {given!r}; drop --units"
            )
        return recorded
    if given is None:
        warnings.warn(
            f"{path}: the {layout} layout records no length unit; assuming m; the authors' own files are in "
            "inches: pass --units inch (or m|mm|cm) to set it",
            UserWarning,
            stacklevel=3,
        )
        return "m"
    return given


@dataclass(frozen=True)
class ImportedCapture:
    """A capture read from a foreign file, in its stored image order, lengths already in metres.

    It is a :class:`~gttdata.capture.views.ViewableCapture`: ``make_view(capture, sequencing)`` gives its
    solver inputs and ground truth. Foreign files carry an order but no clock, so ``timestamp_s`` holds
    each image's time *rank* (unit: one image interval), which is what the order-based methods use.

    Args:
        source: File name, for messages and the default ``none`` permutation seed.
        skeleton: Joint topology (J joints).
        cam_id: Camera of each image, shape ``(N,)`` int, in ``[0, V)``.
        stream_index: Index of each image within its camera stream, shape ``(N,)`` int.
        K: Intrinsics per image, pixels, shape ``(N, 3, 3)``.
        cam_from_world: World→camera transform per image, metres, shape ``(N, 4, 4)``.
        keypoints_px: 2-D joints, pixels, shape ``(N, J, 2)``, NaN where missing.
        visible: Observed mask, shape ``(N, J)``.
        image_size: ``(width, height)`` per camera, shape ``(V, 2)``.
        time_rank: Rank of each image in true time, shape ``(N,)``, or None when the file has no order.
        points3d: Ground-truth joints, metres, shape ``(N, J, 3)``, or None.
        file_units: The length unit the file was read in (converted to metres on import).
    """

    source: str
    skeleton: Skeleton
    cam_id: np.ndarray
    stream_index: np.ndarray
    K: np.ndarray
    cam_from_world: np.ndarray
    keypoints_px: np.ndarray
    visible: np.ndarray
    image_size: np.ndarray
    time_rank: np.ndarray | None = None
    points3d: np.ndarray | None = None
    file_units: str = "m"

    @property
    def n_images(self) -> int:
        """Number of images N."""
        return int(self.cam_id.shape[0])

    @property
    def best_sequencing(self) -> str:
        """The richest sequencing condition this capture supports (``full`` only with a known order)."""
        return "full" if self.time_rank is not None else "partial"

    @property
    def name(self) -> str:
        """The file name (seeds the default ``none`` permutation)."""
        return self.source

    @property
    def timestamp_s(self) -> np.ndarray | None:
        """Time rank of each image as float, shape ``(N,)``, or None without a global order."""
        return None if self.time_rank is None else self.time_rank.astype(np.float64)

    @property
    def global_order(self) -> np.ndarray:
        """Rank of each image in true time, shape ``(N,)`` int64; -1 without a global order."""
        if self.time_rank is None:
            return np.full(self.n_images, -1, dtype=np.int64)
        return self.time_rank.astype(np.int64)

    @functools.cached_property
    def _affinity(self) -> tuple[np.ndarray, np.ndarray]:
        n = self.n_images
        if self.time_rank is None or self.points3d is None:
            # No time order in the file: MPJPE can be scored, sequence recovery cannot.
            return np.full((n, 2), -1, dtype=np.int32), np.zeros((n, 2))
        # The filled-in X (missing joints included) is exactly what GroundTruth describes; fine for A^G.
        return temporal_affinity(self.time_rank.astype(np.float64), self.cam_id, np.nan_to_num(self.points3d))

    @property
    def affinity_nbr(self) -> np.ndarray:
        """Temporal neighbours (stored indices) from the file's order, shape ``(N, 2)``, -1 where none."""
        return self._affinity[0]

    @property
    def affinity_w(self) -> np.ndarray:
        """Interpolation weights of those neighbours, shape ``(N, 2)``."""
        return self._affinity[1]
