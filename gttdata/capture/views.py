"""Sequencing views: what a solver may see of a capture under none / partial / full sequencing."""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from gttdata.capture.sample import CaptureSample, affinity_from_neighbours
from gttdata.errors import RigError
from gttdata.skeleton import Skeleton

__all__ = ["SEQUENCING", "Observations", "GroundTruth", "make_view"]

#: The three sequencing conditions of the paper.
SEQUENCING: tuple[str, ...] = ("none", "partial", "full")


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
        for name in ("K", "cam_from_world"):  # NaN cameras used to surface as "no triangulable joint"
            value = np.asarray(getattr(self, name), dtype=np.float64)
            bad = np.asarray(~np.isfinite(value.reshape(value.shape[0], -1)).all(axis=1), dtype=bool)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise RigError(
                    f"cameras: {name}: expected finite values for every image, found NaN or inf in "
                    f"{int(bad.sum())} of {bad.shape[0]} images (first: image {i}, camera {int(self.cam_id[i])})"
                )

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
        px = np.where(self.visible[..., None], self.keypoints_px, 0.0).astype(np.float64)
        h = np.concatenate([px, np.ones(px.shape[:-1] + (1,))], axis=-1)
        Kinv = np.linalg.inv(self.K)
        d = np.einsum("nab,njb->nja", Kinv, h)
        d = np.einsum("nba,njb->nja", self.cam_from_world[:, :3, :3], d)
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


def _view_permutation(sample: CaptureSample, sequencing: str, seed: int | None) -> np.ndarray:
    n = sample.n_images
    if sequencing == "full":
        return np.argsort(sample.timestamp_s, kind="stable")
    if sequencing == "partial":
        return np.lexsort((sample.stream_index, sample.cam_id))
    s = zlib.crc32(sample.name.encode()) if seed is None else seed
    return np.random.default_rng(s).permutation(n)


def _stream_times(sample: CaptureSample, perm: np.ndarray) -> np.ndarray | None:
    """Per-image times on each camera's own clock, or None.

    What each camera's own clock says of its images: ``frame / fps`` at the camera's nominal rate, with
    the camera's frame counter (gaps where frames were dropped), from the capture parameters in ``meta``;
    None when ``meta`` does not record the rates. Offsets, drift and jitter are not in it (they are what
    clock recovery estimates).
    """
    fps = sample.meta.get("capture", {}).get("fps_hz") if isinstance(sample.meta, dict) else None
    if not fps or len(fps) <= int(sample.cam_id.max(initial=0)):
        return None
    frame = np.asarray(sample.meta.get("frame_number", sample.stream_index), dtype=np.float64)
    if frame.shape != sample.cam_id.shape:
        return None
    return (frame / np.asarray(fps, dtype=np.float64)[sample.cam_id])[perm]


def make_view(
    sample: CaptureSample, sequencing: str, *, seed: int | None = None
) -> tuple[Observations, GroundTruth]:
    """Split a sample into solver inputs and ground truth for one sequencing condition.

    Args:
        sample: The stored capture.
        sequencing: ``"none"``, ``"partial"`` or ``"full"``.
        seed: Seed of the random image permutation under ``"none"`` (default: from the sample name,
            so a view is reproducible).

    Returns:
        ``(observations, ground_truth)``, both in the view's image order.
    """
    if sequencing not in SEQUENCING:
        raise ValueError(f"sequencing must be one of {SEQUENCING}, got {sequencing!r}")
    perm = _view_permutation(sample, sequencing, seed)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.shape[0])
    nbr = sample.affinity_nbr[perm]
    nbr = np.where(nbr >= 0, inv[np.maximum(nbr, 0)], -1).astype(np.int32)
    obs = Observations(
        sequencing=sequencing,
        skeleton=sample.skeleton,
        cam_id=sample.cam_id[perm].copy(),
        K=sample.K[perm].copy(),
        cam_from_world=sample.cam_from_world[perm].copy(),
        keypoints_px=sample.keypoints_px[perm].copy(),
        visible=sample.visible[perm].copy(),
        image_size=np.asarray(sample.image_size).copy(),
        stream_index=None if sequencing == "none" else sample.stream_index[perm].copy(),
        timestamp_s=sample.timestamp_s[perm].copy() if sequencing == "full" else None,
        stream_time_s=None if sequencing == "none" else _stream_times(sample, perm),
    )
    gt = GroundTruth(
        points3d=sample.points3d[perm].copy(),
        timestamp_s=sample.timestamp_s[perm].copy(),
        global_order=sample.global_order[perm].copy(),
        affinity_nbr=nbr,
        affinity_w=sample.affinity_w[perm].copy(),
        perm=perm,
    )
    return obs, gt
