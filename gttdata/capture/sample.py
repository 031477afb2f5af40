"""CaptureSample: one simulated unsynchronized multi-camera capture with its ground truth."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gttdata.skeleton import Skeleton

__all__ = ["CaptureSample", "affinity_from_neighbours", "temporal_affinity"]


@dataclass(frozen=True)
class CaptureSample:
    """A capture of N images of one subject with J joints, stored in true global time order.

    Image ``n`` is taken by camera ``cam_id[n]`` at ``timestamp_s[n]``; images are stored sorted by
    timestamp, so ``global_order == arange(N)`` for a freshly simulated sample. Consumers must not rely
    on the storage order: :func:`gttdata.capture.views.make_view` hides it per sequencing condition.

    Args:
        name: Sample id, unique in a dataset (e.g. ``"train/000017"``).
        motion_name: Name of the source motion (splits are by motion).
        skeleton: Joint topology (J joints).
        cam_id: Camera index of each image, shape ``(N,)`` int32, in ``[0, V)``.
        timestamp_s: Capture time of each image, seconds, shape ``(N,)`` float64.
        stream_index: Index of each image within its camera's stream (0, 1, ...), shape ``(N,)`` int32.
        global_order: Rank of each image in true time order, shape ``(N,)`` int32.
        keypoints_px: Observed (noisy) 2-D joints in pixels, shape ``(N, J, 2)`` float32; NaN where missing.
        visible: Whether each joint is observed, shape ``(N, J)`` bool.
        keypoints_gt_px: Noise-free projections of the ground truth, pixels, shape ``(N, J, 2)`` float32.
        K: Intrinsics of each image's camera, pixels, shape ``(N, 3, 3)`` float64.
        cam_from_world: World→camera transform of each image (after any per-image perturbation),
            shape ``(N, 4, 4)`` float64.
        image_size: ``(width, height)`` of each camera in pixels, shape ``(V, 2)`` int32.
        points3d: Ground-truth joints in world, metres, shape ``(N, J, 3)`` float64.
        affinity_nbr: For each image, its previous and next image in true time taken by a *different*
            camera, shape ``(N, 2)`` int32, ``-1`` where none exists.
        affinity_w: Continuous ground-truth affinity: the weights that best express ``points3d[n]`` as an
            affine combination of its two temporal neighbours, shape ``(N, 2)`` float64 (0 where missing).
        variant: Name of the input variant (``"orig"`` or an augmentation name).
        meta: Capture parameters (noise sigma, rates, seeds...), JSON-serialisable.
    """

    name: str
    motion_name: str
    skeleton: Skeleton
    cam_id: np.ndarray
    timestamp_s: np.ndarray
    stream_index: np.ndarray
    global_order: np.ndarray
    keypoints_px: np.ndarray
    visible: np.ndarray
    keypoints_gt_px: np.ndarray
    K: np.ndarray
    cam_from_world: np.ndarray
    image_size: np.ndarray
    points3d: np.ndarray
    affinity_nbr: np.ndarray
    affinity_w: np.ndarray
    variant: str = "orig"
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n = int(np.asarray(self.cam_id).shape[0])
        j = self.skeleton.n_joints
        expect = {
            "cam_id": (n,),
            "timestamp_s": (n,),
            "stream_index": (n,),
            "global_order": (n,),
            "keypoints_px": (n, j, 2),
            "visible": (n, j),
            "keypoints_gt_px": (n, j, 2),
            "K": (n, 3, 3),
            "cam_from_world": (n, 4, 4),
            "points3d": (n, j, 3),
            "affinity_nbr": (n, 2),
            "affinity_w": (n, 2),
        }
        for key, shape in expect.items():
            got = np.shape(getattr(self, key))
            if got != shape:
                raise ValueError(f"sample {self.name!r}: {key} must have shape {shape}, got {got}")
        if np.ndim(self.image_size) != 2 or np.shape(self.image_size)[1] != 2:
            raise ValueError(
                f"sample {self.name!r}: image_size must have shape (V, 2), got {np.shape(self.image_size)}"
            )

    @property
    def n_images(self) -> int:
        """Number of images N."""
        return int(self.cam_id.shape[0])

    @property
    def n_joints(self) -> int:
        """Number of joints J."""
        return self.skeleton.n_joints

    @property
    def n_cameras(self) -> int:
        """Number of cameras V."""
        return int(self.image_size.shape[0])

    def affinity_binary(self) -> np.ndarray:
        """Symmetric binary ground-truth affinity A^G, shape ``(N, N)`` (see :func:`affinity_from_neighbours`)."""
        return affinity_from_neighbours(self.affinity_nbr, self.affinity_w, binary=True)

    def affinity_continuous(self) -> np.ndarray:
        """Row-wise continuous ground-truth affinity, shape ``(N, N)`` (see :func:`affinity_from_neighbours`)."""
        return affinity_from_neighbours(self.affinity_nbr, self.affinity_w, binary=False)

    def replace(self, **changes) -> CaptureSample:
        """A copy with fields replaced (dataclasses.replace)."""
        return replace(self, **changes)


def affinity_from_neighbours(nbr: np.ndarray, w: np.ndarray, *, binary: bool) -> np.ndarray:
    """Dense ground-truth affinity from per-image temporal neighbours.

    Args:
        nbr: Previous/next neighbour of each image, shape ``(N, 2)``, -1 where none.
        w: Interpolation weight of each neighbour, shape ``(N, 2)``.
        binary: True: symmetric 0/1 matrix linking temporally consecutive images of different cameras.
            False: row n holds the interpolation weights of image n's neighbours (not symmetric).

    Returns:
        Matrix of shape ``(N, N)`` float64.
    """
    n = nbr.shape[0]
    A = np.zeros((n, n))
    rows = np.repeat(np.arange(n), 2)
    cols = nbr.ravel()
    ok = cols >= 0
    A[rows[ok], cols[ok]] = 1.0 if binary else w.ravel()[ok]
    return np.maximum(A, A.T) if binary else A


def temporal_affinity(
    timestamp_s: np.ndarray, cam_id: np.ndarray, points3d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Ground-truth temporal neighbours and interpolation weights.

    For each image, the previous and next image in true time taken by another camera; the weights
    ``(a, b)`` minimise ``||X_n - a X_prev - b X_next||`` subject to ``a + b = 1`` (clipped to [0, 1]),
    which for linear motion is the timestamp ratio.

    Args:
        timestamp_s: Image times, seconds, shape ``(N,)``.
        cam_id: Camera of each image, shape ``(N,)``.
        points3d: Ground-truth joints, metres, shape ``(N, J, 3)``.

    Returns:
        ``(nbr, w)``: shapes ``(N, 2)`` int32 (``-1`` where none) and ``(N, 2)`` float64.
    """
    t = np.asarray(timestamp_s, dtype=np.float64)
    cam = np.asarray(cam_id)
    n = t.shape[0]
    order = np.argsort(t, kind="stable")
    nbr = np.full((n, 2), -1, dtype=np.int32)
    w = np.zeros((n, 2))
    pos = np.empty(n, dtype=np.int64)
    pos[order] = np.arange(n)
    for i in range(n):
        k = pos[i]
        prev = next((order[m] for m in range(k - 1, -1, -1) if cam[order[m]] != cam[i]), -1)
        nxt = next((order[m] for m in range(k + 1, n) if cam[order[m]] != cam[i]), -1)
        nbr[i] = (prev, nxt)
        if prev >= 0 and nxt >= 0:
            d = (points3d[prev] - points3d[nxt]).ravel()
            e = (points3d[i] - points3d[nxt]).ravel()
            denom = float(d @ d)
            if denom > 1e-18:
                a = float(np.clip(d @ e / denom, 0.0, 1.0))
            else:
                a = float(np.clip((t[nxt] - t[i]) / max(t[nxt] - t[prev], 1e-12), 0.0, 1.0))
            w[i] = (a, 1.0 - a)
        elif prev >= 0:
            w[i, 0] = 1.0
        elif nxt >= 0:
            w[i, 1] = 1.0
    return nbr, w
