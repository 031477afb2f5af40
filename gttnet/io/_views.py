"""Imported captures and their sequencing views, mirroring gttdata's make_view for files from other tools."""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from gttdata.capture.sample import temporal_affinity
from gttdata.capture.views import SEQUENCING, GroundTruth, Observations
from gttdata.skeleton import Skeleton, cmu31
from gttnet.errors import SequencingError

__all__ = ["UNITS", "ImportedCapture", "default_skeleton", "make_imported_view", "view_permutation"]

#: Length units accepted by the importers, in metres.
UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "inch": 0.0254}


def default_skeleton(n_joints: int) -> Skeleton:
    """CMU-31 for 31 joints, else a star topology named ``imported<J>`` (joint 0 the root)."""
    if n_joints == 31:
        return cmu31()
    return Skeleton(
        name=f"imported{n_joints}",
        joint_names=tuple(f"j{i}" for i in range(n_joints)),
        parents=(-1,) + (0,) * (n_joints - 1),
    )


@dataclass(frozen=True)
class ImportedCapture:
    """A capture read from a foreign file, in its stored image order, lengths already in metres.

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

    @property
    def n_images(self) -> int:
        """Number of images N."""
        return int(self.cam_id.shape[0])

    @property
    def best_sequencing(self) -> str:
        """The richest sequencing condition this capture supports (``full`` only with a known order)."""
        return "full" if self.time_rank is not None else "partial"


def view_permutation(cap: ImportedCapture, sequencing: str, seed: int | None = None) -> np.ndarray:
    """Stored index of each view image under a sequencing condition (see :func:`make_imported_view`)."""
    if sequencing == "full":
        if cap.time_rank is None:
            raise SequencingError(
                f"{cap.source}: sequencing 'full' needs the global image order, which the file does not hold; "
                "use --sequencing partial or none"
            )
        return np.argsort(cap.time_rank, kind="stable")
    if sequencing == "partial":
        return np.lexsort((cap.stream_index, cap.cam_id))
    s = zlib.crc32(cap.source.encode()) if seed is None else seed
    return np.random.default_rng(s).permutation(cap.n_images)


def _ground_truth(cap: ImportedCapture, perm: np.ndarray) -> GroundTruth | None:
    if cap.points3d is None:
        return None
    n = cap.n_images
    X = cap.points3d[perm]
    if cap.time_rank is None:
        # No time order in the file: MPJPE can be scored, sequence recovery cannot.
        return GroundTruth(
            points3d=X,
            timestamp_s=np.full(n, np.nan),
            global_order=np.full(n, -1, dtype=np.int64),
            affinity_nbr=np.full((n, 2), -1, dtype=np.int32),
            affinity_w=np.zeros((n, 2)),
            perm=perm,
        )
    rank = cap.time_rank[perm].astype(np.int64)
    # The filled-in X (missing joints included) is exactly what GroundTruth describes; fine for A^G.
    nbr, w = temporal_affinity(rank.astype(np.float64), cap.cam_id[perm], np.nan_to_num(X))
    return GroundTruth(
        points3d=X,
        timestamp_s=rank.astype(np.float64),
        global_order=rank,
        affinity_nbr=nbr,
        affinity_w=w,
        perm=perm,
    )


def make_imported_view(
    cap: ImportedCapture, sequencing: str, *, seed: int | None = None
) -> tuple[Observations, GroundTruth | None]:
    """Solver inputs (and ground truth, when the file has it) for one sequencing condition.

    As :func:`gttdata.capture.views.make_view`: ``none`` permutes the images at random (seeded by the
    file name unless ``seed`` is given), ``partial`` groups them by camera in stream order, ``full``
    sorts them by the file's global order. Foreign files carry an order but no clock, so under
    ``full`` the observations' ``timestamp_s`` holds each image's time *rank* (unit: one image
    interval), which is what the order-based methods use.

    Raises:
        SequencingError: ``full`` requested for a file without a global order.
    """
    if sequencing not in SEQUENCING:
        raise ValueError(f"sequencing must be one of {SEQUENCING}, got {sequencing!r}")
    perm = view_permutation(cap, sequencing, seed)
    obs = Observations(
        sequencing=sequencing,
        skeleton=cap.skeleton,
        cam_id=cap.cam_id[perm].copy(),
        K=cap.K[perm].copy(),
        cam_from_world=cap.cam_from_world[perm].copy(),
        keypoints_px=cap.keypoints_px[perm].copy(),
        visible=cap.visible[perm].copy(),
        image_size=np.asarray(cap.image_size).copy(),
        stream_index=None if sequencing == "none" else cap.stream_index[perm].copy(),
        timestamp_s=cap.time_rank[perm].astype(np.float64) if sequencing == "full" else None,
    )
    return obs, _ground_truth(cap, perm)
