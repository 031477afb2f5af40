"""Sequencing views: what a solver may see of a capture under none / partial / full sequencing."""

from __future__ import annotations

import zlib
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from gttdata.capture.sample import affinity_from_neighbours
from gttdata.errors import KeypointFormatError, RigError, SequencingError
from gttdata.skeleton import Skeleton

__all__ = [
    "SEQUENCING",
    "Observations",
    "GroundTruth",
    "PER_IMAGE_FIELDS",
    "ViewableCapture",
    "make_view",
    "view_permutation",
]

#: The three sequencing conditions of the paper.
SEQUENCING: tuple[str, ...] = ("none", "partial", "full")


#: The fields of :class:`Observations` with one entry per image (leading axis N).
PER_IMAGE_FIELDS = (
    "cam_id",
    "K",
    "cam_from_world",
    "keypoints_px",
    "visible",
    "stream_index",
    "timestamp_s",
    "stream_time_s",
    "confidence",
)


@dataclass(frozen=True)
class Observations:
    """The inputs of a reconstruction: 2-D joints and cameras, and only the timing the condition allows.

    Image order carries no information beyond what ``sequencing`` grants:
    * ``none``: images are randomly permuted; ``stream_index`` and ``timestamp_s`` are None.
    * ``partial``: images are grouped by camera (ascending ``cam_id``), each stream in its own order;
      ``stream_index`` is given, ``timestamp_s`` is None. The streams' relative timing is unknown.
    * ``full``: images are in true global time order; ``timestamp_s`` and ``stream_index`` are given.

    Args:
        sequencing: One of :data:`SEQUENCING`.
        skeleton: Joint topology (J joints).
        cam_id: Camera of each image, shape ``(N,)`` int.
        K: Intrinsics per image, pixels, shape ``(N, 3, 3)``.
        cam_from_world: World→camera transform per image, shape ``(N, 4, 4)``.
        keypoints_px: 2-D joints, pixels, shape ``(N, J, 2)``; NaN where missing.
        visible: Observed-joint mask, shape ``(N, J)`` bool.
        image_size: ``(width, height)`` per camera, shape ``(V, 2)``.
        stream_index: Index within the camera stream, shape ``(N,)``, or None. May skip values where a
            camera dropped frames (a timestamp file says so).
        timestamp_s: Capture times, seconds, shape ``(N,)``, or None.
        stream_time_s: Time of each image on its own camera's clock, seconds, shape ``(N,)``, or None:
            known per-camera timing (``frame / fps`` or a per-frame timestamp file) whose offsets
            between cameras are unknown. Allowed under ``partial`` and ``full`` (it is what clock
            recovery starts from); never under ``none``.
        confidence: Detector confidence of each joint in ``[0, 1]``, shape ``(N, J)``, or None (all
            observed joints count fully). Solvers that weigh ray residuals use it as a per-observation
            weight; joints below the caller's confidence threshold are already marked missing.
    """

    sequencing: str
    skeleton: Skeleton
    cam_id: np.ndarray
    K: np.ndarray
    cam_from_world: np.ndarray
    keypoints_px: np.ndarray
    visible: np.ndarray
    image_size: np.ndarray
    stream_index: np.ndarray | None = None
    timestamp_s: np.ndarray | None = None
    stream_time_s: np.ndarray | None = None
    confidence: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.sequencing not in SEQUENCING:
            raise ValueError(f"sequencing must be one of {SEQUENCING}, got {self.sequencing!r}")
        if self.sequencing == "none" and (self.stream_index is not None or self.timestamp_s is not None):
            raise ValueError("sequencing 'none' must not carry stream_index or timestamp_s")
        if self.sequencing == "partial" and (self.stream_index is None or self.timestamp_s is not None):
            raise ValueError("sequencing 'partial' needs stream_index and must not carry timestamp_s")
        if self.sequencing == "full" and self.timestamp_s is None:
            raise ValueError("sequencing 'full' needs timestamp_s")
        if self.sequencing == "none" and self.stream_time_s is not None:
            raise ValueError("sequencing 'none' must not carry stream_time_s")
        n, j = np.shape(self.keypoints_px)[:2]
        if self.stream_time_s is not None and np.shape(self.stream_time_s) != (n,):
            raise ValueError(f"stream_time_s must have shape ({n},), got {np.shape(self.stream_time_s)}")
        if self.confidence is not None and np.shape(self.confidence) != (n, j):
            raise ValueError(f"confidence must have shape ({n}, {j}), got {np.shape(self.confidence)}")
        self._check_keypoints_and_times(n, j)
        for name in ("K", "cam_from_world"):  # NaN cameras used to surface as "no triangulable joint"
            value = np.asarray(getattr(self, name), dtype=np.float64)
            bad = np.asarray(~np.isfinite(value.reshape(value.shape[0], -1)).all(axis=1), dtype=bool)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise RigError(
                    f"cameras: {name}: expected finite values for every image, found NaN or inf in "
                    f"{int(bad.sum())} of {bad.shape[0]} images (first: image {i}, camera {int(self.cam_id[i])})"
                )

    def _check_keypoints_and_times(self, n: int, j: int) -> None:
        """Visible joints have finite pixels; timestamps are finite and, under ``full``, order something."""
        vis = np.asarray(self.visible, dtype=bool)
        if vis.shape != (n, j):
            raise ValueError(f"visible must have shape ({n}, {j}) like keypoints_px, got {vis.shape}")
        lost = vis & ~np.isfinite(np.asarray(self.keypoints_px, dtype=np.float64)).all(axis=-1)
        if lost.any():  # each solver used to fail on these in its own words
            i, p = (int(x) for x in np.argwhere(lost)[0])
            raise KeypointFormatError(
                f"keypoints_px: expected finite pixels for every visible joint, found NaN or inf in "
                f"{int(lost.sum())} (first: image {i}, joint {p} {self.skeleton.joint_names[p]!r}); "
                "mark them missing in visible"
            )
        if self.timestamp_s is not None:
            t = np.asarray(self.timestamp_s, dtype=np.float64)
            if t.shape != (n,) or not np.isfinite(t).all():
                raise SequencingError(
                    f"timestamp_s: expected {n} finite times, seconds; got shape {t.shape}, "
                    f"{int((~np.isfinite(t)).sum())} NaN or inf"
                )
            if self.sequencing == "full" and n > 1 and float(np.ptp(t)) == 0.0:
                raise SequencingError(
                    f"timestamp_s: all {n} timestamps are {float(t[0])!r} s, which orders nothing; give the "
                    "capture times, or use sequencing 'partial' or 'none'"
                )

    def take(self, rows: np.ndarray) -> Observations:
        """The images ``rows`` (indices or a mask over N), every per-image field indexed alike.

        The sequencing condition is kept: a caller that reorders a ``partial`` or ``full`` view keeps its
        order rules (or replaces the timing fields itself).
        """
        picked = {}
        for name in PER_IMAGE_FIELDS:
            value = getattr(self, name)
            if value is not None:
                picked[name] = np.asarray(value)[rows]
        return replace(self, **picked)

    def weights(self) -> np.ndarray:
        """Per-observation weight, shape ``(N, J)``: the confidence where given, else 1; 0 where missing."""
        w = np.ones(self.visible.shape) if self.confidence is None else np.nan_to_num(self.confidence)
        return np.where(self.visible, np.clip(w, 0.0, 1.0), 0.0)

    @property
    def n_images(self) -> int:
        """Number of images N."""
        return int(self.cam_id.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return int(self.keypoints_px.shape[1])

    def centers(self) -> np.ndarray:
        """Camera centre of each image in world, metres, shape ``(N, 3)``."""
        R = self.cam_from_world[:, :3, :3]
        t = self.cam_from_world[:, :3, 3]
        return -np.einsum("nji,nj->ni", R, t)

    def rays(self) -> np.ndarray:
        """Unit viewing ray of every joint in world, shape ``(N, J, 3)``; zero where missing.

        ``r = R^T K^-1 [u, v, 1]^T`` normalised, with R the world→camera rotation.
        """
        # world-from-pixel map R^T K^-1 of every image, shape (N, 3, 3), applied as one batched matmul
        M = self.cam_from_world[:, :3, :3].transpose(0, 2, 1) @ np.linalg.inv(self.K)
        px = np.where(self.visible[..., None], self.keypoints_px, 0.0).astype(np.float64)
        d = px @ M[:, :, :2].transpose(0, 2, 1) + M[:, None, :, 2]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        return np.where(self.visible[..., None], d, 0.0)


@dataclass(frozen=True)
class GroundTruth:
    """Ground truth aligned with an :class:`Observations` view. Never passed to a solver.

    Args:
        points3d: Joints in world, metres, shape ``(N, J, 3)``.
        timestamp_s: True capture times, seconds, shape ``(N,)``.
        global_order: Rank of each image in true time, shape ``(N,)``.
        affinity_nbr: Temporal neighbours (view indices), shape ``(N, 2)``, -1 where none.
        affinity_w: Interpolation weights of those neighbours, shape ``(N, 2)``.
        perm: Stored index of each view image, shape ``(N,)``.
    """

    points3d: np.ndarray
    timestamp_s: np.ndarray
    global_order: np.ndarray
    affinity_nbr: np.ndarray
    affinity_w: np.ndarray
    perm: np.ndarray

    def affinity_binary(self) -> np.ndarray:
        """Symmetric binary A^G in view order, shape ``(N, N)``."""
        return affinity_from_neighbours(self.affinity_nbr, self.affinity_w, binary=True)

    def affinity_continuous(self) -> np.ndarray:
        """Row-wise continuous A^G in view order, shape ``(N, N)``."""
        return affinity_from_neighbours(self.affinity_nbr, self.affinity_w, binary=False)


class ViewableCapture(Protocol):
    """What :func:`make_view` needs of a capture, every array in stored image order (N images, J joints).

    :class:`~gttdata.capture.sample.CaptureSample` (simulated) and imported captures
    (``gttnet.io.ImportedCapture``) both provide it. A capture with a ``meta`` dict recording its
    cameras' frame rates (simulated ones) also gives the views each camera's own clock.
    """

    @property
    def name(self) -> str:
        """Capture name; seeds the default ``none`` permutation."""

    @property
    def skeleton(self) -> Skeleton:
        """Joint topology (J joints)."""

    @property
    def cam_id(self) -> np.ndarray:
        """Camera of each image, shape ``(N,)`` int."""

    @property
    def stream_index(self) -> np.ndarray:
        """Index within the camera stream, shape ``(N,)`` int."""

    @property
    def K(self) -> np.ndarray:
        """Intrinsics per image, pixels, shape ``(N, 3, 3)``."""

    @property
    def cam_from_world(self) -> np.ndarray:
        """World→camera transform per image, metres, shape ``(N, 4, 4)``."""

    @property
    def keypoints_px(self) -> np.ndarray:
        """2-D joints, pixels, shape ``(N, J, 2)``; NaN where missing."""

    @property
    def visible(self) -> np.ndarray:
        """Observed-joint mask, shape ``(N, J)`` bool."""

    @property
    def image_size(self) -> np.ndarray:
        """``(width, height)`` per camera, shape ``(V, 2)``."""

    @property
    def timestamp_s(self) -> np.ndarray | None:
        """Capture times, seconds (time ranks for files with an order but no clock), ``(N,)``; None: unknown."""

    @property
    def points3d(self) -> np.ndarray | None:
        """Ground-truth joints in world, metres, shape ``(N, J, 3)``, or None when unknown."""

    @property
    def global_order(self) -> np.ndarray:
        """Rank of each image in true time, shape ``(N,)``; -1 where unknown."""

    @property
    def affinity_nbr(self) -> np.ndarray:
        """Temporal neighbours (stored indices), shape ``(N, 2)``, -1 where none."""

    @property
    def affinity_w(self) -> np.ndarray:
        """Interpolation weights of those neighbours, shape ``(N, 2)``."""


def view_permutation(capture: ViewableCapture, sequencing: str, seed: int | None = None) -> np.ndarray:
    """Stored index of each view image under a sequencing condition, shape ``(N,)``.

    ``full`` sorts by time, ``partial`` groups by camera in stream order, ``none`` permutes at random
    (seeded by ``seed``, else by the capture's name, so a view is reproducible).

    Raises:
        SequencingError: ``full`` for a capture without a global order.
    """
    if sequencing == "full":
        if capture.timestamp_s is None:
            raise SequencingError(
                f"{capture.name}: sequencing 'full' needs the global image order, which the file does not "
                "hold; use --sequencing partial or none"
            )
        return np.argsort(capture.timestamp_s, kind="stable")
    if sequencing == "partial":
        return np.lexsort((capture.stream_index, capture.cam_id))
    s = zlib.crc32(capture.name.encode()) if seed is None else seed
    return np.random.default_rng(s).permutation(capture.cam_id.shape[0])


def _stream_times(capture: ViewableCapture, perm: np.ndarray) -> np.ndarray | None:
    """What each camera's own clock says of its images, or None.

    ``frame / fps`` at the camera's nominal rate, with the camera's frame counter (gaps where frames were
    dropped), from the capture parameters in ``meta`` (simulated captures); None when the capture has no
    ``meta`` recording the rates. Offsets, drift and jitter are not in it (they are what clock recovery
    estimates).
    """
    meta = getattr(capture, "meta", None)
    if not isinstance(meta, dict):
        return None
    fps = meta.get("capture", {}).get("fps_hz")
    if not fps or len(fps) <= int(capture.cam_id.max(initial=0)):
        return None
    frame = np.asarray(meta.get("frame_number", capture.stream_index), dtype=np.float64)
    if frame.shape != capture.cam_id.shape:
        return None
    return (frame / np.asarray(fps, dtype=np.float64)[capture.cam_id])[perm]


def make_view(
    capture: ViewableCapture, sequencing: str, *, seed: int | None = None
) -> tuple[Observations, GroundTruth]:
    """Split a capture into solver inputs and ground truth for one sequencing condition.

    Args:
        capture: A stored capture (any :class:`ViewableCapture`).
        sequencing: ``"none"``, ``"partial"`` or ``"full"``.
        seed: Seed of the random image permutation under ``"none"`` (default: from the capture name,
            so a view is reproducible).

    Returns:
        ``(observations, ground_truth)``, both in the view's image order; the ground truth is None
        (typed as present, since simulated captures always have it) when ``capture.points3d`` is None.

    Raises:
        SequencingError: ``full`` for a capture without a global order.
    """
    if sequencing not in SEQUENCING:
        raise ValueError(f"sequencing must be one of {SEQUENCING}, got {sequencing!r}")
    perm = view_permutation(capture, sequencing, seed)
    times = capture.timestamp_s
    obs = Observations(
        sequencing=sequencing,
        skeleton=capture.skeleton,
        cam_id=capture.cam_id[perm].copy(),
        K=capture.K[perm].copy(),
        cam_from_world=capture.cam_from_world[perm].copy(),
        keypoints_px=capture.keypoints_px[perm].copy(),
        visible=capture.visible[perm].copy(),
        image_size=np.asarray(capture.image_size).copy(),
        stream_index=None if sequencing == "none" else capture.stream_index[perm].copy(),
        timestamp_s=times[perm].astype(np.float64) if sequencing == "full" and times is not None else None,
        stream_time_s=None if sequencing == "none" else _stream_times(capture, perm),
    )
    X = capture.points3d
    if X is None:
        return obs, None  # type: ignore[return-value]
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.shape[0])
    nbr = capture.affinity_nbr[perm]
    nbr = np.where(nbr >= 0, inv[np.maximum(nbr, 0)], -1).astype(np.int32)
    gt = GroundTruth(
        points3d=X[perm].copy(),
        timestamp_s=np.full(perm.shape[0], np.nan) if times is None else times[perm].astype(np.float64),
        global_order=capture.global_order[perm].copy(),
        affinity_nbr=nbr,
        affinity_w=capture.affinity_w[perm].copy(),
        perm=perm,
    )
    return obs, gt
