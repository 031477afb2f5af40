"""The 2-D keypoint noise of a capture, read off its own camera streams, and the ray weight it implies.

Within one camera, three consecutive frames of a joint give the second difference
``d = x[k-1] - 2 x[k] + x[k+1]`` (pixels, per image axis). Independent Gaussian noise of std sigma makes
``d`` spread with std ``sqrt(6) sigma``; the motion adds its acceleration times the frame interval squared,
which is small for most joints at video rates. A robust spread of ``d`` (1.4826 times the median absolute
value) divided by ``sqrt(6)`` therefore estimates sigma, from above. Each camera gives its own estimate
and the smallest is kept: the noise is the detector's, while the motion term grows with the frame
interval, so the fastest camera is the least biased (on the procedural validation captures, 7.5-30 Hz,
0.8-4.7 px: within +0.5 px of the true noise with the cameras' frame order given, except where motion is
fast for the rate).
"""

from __future__ import annotations

import warnings

import numpy as np

from gttnet.solvers.numpy_xstep import noise_aware_lambda2

__all__ = ["MIN_SAMPLES", "auto_lambda2", "stream_noise_px"]

#: Second differences (joint x axis values) a camera needs for its noise estimate to count.
MIN_SAMPLES = 50


def stream_noise_px(
    keypoints_px: np.ndarray, visible: np.ndarray, cam_id: np.ndarray, stream_index: np.ndarray
) -> float | None:
    """Std of the 2-D keypoint noise, pixels, from second differences along each camera's frames.

    Only triples of frames whose stream indices follow one another (no dropped frame between them) and
    where the joint is visible in all three count.

    Args:
        keypoints_px: 2-D joints, pixels, shape ``(N, J, 2)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        cam_id: Camera of each image, shape ``(N,)``.
        stream_index: Each image's frame index within its camera (given, or estimated, e.g. by
            :func:`gttnet.model.inputs.order_streams`), shape ``(N,)``.

    Returns:
        The smallest per-camera estimate over cameras with at least :data:`MIN_SAMPLES` values, or None
        when no camera has that many.

    Example:
        >>> rng = np.random.default_rng(0)
        >>> px = np.linspace(0, 50, 400)[:, None, None] + rng.normal(0, 2.0, (400, 3, 2))
        >>> s = stream_noise_px(px, np.ones((400, 3), bool), np.zeros(400, int), np.arange(400))
        >>> round(s, 1)
        2.0
    """
    px = np.asarray(keypoints_px, dtype=np.float64)
    vis = np.asarray(visible, dtype=bool)
    cam = np.asarray(cam_id)
    si = np.asarray(stream_index)
    best: float | None = None
    for c in np.unique(cam):
        idx = np.flatnonzero(cam == c)
        idx = idx[np.argsort(si[idx], kind="stable")]
        step = np.diff(si[idx])
        run = (step[:-1] == 1) & (step[1:] == 1)
        a, b, d = idx[:-2][run], idx[1:-1][run], idx[2:][run]
        both = vis[a] & vis[b] & vis[d]
        values = np.abs(px[a] - 2.0 * px[b] + px[d])[both].ravel()
        if values.size >= MIN_SAMPLES:
            sigma = 1.4826 * float(np.median(values)) / float(np.sqrt(6.0))
            best = sigma if best is None else min(best, sigma)
    return best


def auto_lambda2(
    keypoints_px: np.ndarray,
    visible: np.ndarray,
    cam_id: np.ndarray,
    stream_index: np.ndarray,
    K: np.ndarray,
    cam_from_world: np.ndarray,
    points3d: np.ndarray,
    *,
    min_sigma_px: float = 0.1,
) -> tuple[np.ndarray | None, float | None]:
    """Per-image ray weights for this capture's own noise (:func:`~gttnet.solvers.xstep.noise_aware_lambda2`).

    A pixel error moves a point off its ray in proportion to its depth, so each image gets the weight of
    its own depth: the noise comes from :func:`stream_noise_px` (floored at ``min_sigma_px``), the focal
    length from the image's ``K``, the depth from the median camera-frame depth of the image's visible
    joints in ``points3d`` (e.g. the pseudo-triangulation; images without one take the capture's median).

    Args:
        keypoints_px: 2-D joints, pixels, shape ``(N, J, 2)``.
        visible: Observed-joint mask, shape ``(N, J)``.
        cam_id: Camera of each image, shape ``(N,)``.
        stream_index: Frame index of each image within its camera, shape ``(N,)``.
        K: Intrinsics per image, pixels, shape ``(N, 3, 3)``.
        cam_from_world: World→camera transform per image, shape ``(N, 4, 4)``.
        points3d: A first estimate of the joints in world, metres, shape ``(N, J, 3)``.
        min_sigma_px: Smallest noise used (noise-free input would otherwise ask for an unbounded weight).

    Returns:
        ``(lambda2, sigma_px)``: lambda2 of shape ``(N,)``, or None (pinned rays) when the streams are too
        short to measure the noise (sigma_px None too) or no visible joint lies in front of its camera.
    """
    sigma = stream_noise_px(keypoints_px, visible, cam_id, stream_index)
    if sigma is None:
        return None, None
    T = np.asarray(cam_from_world, dtype=np.float64)
    X = np.asarray(points3d, dtype=np.float64)
    depth = np.einsum("nk,njk->nj", T[:, 2, :3], X) + T[:, None, 2, 3]
    ok = np.asarray(visible, dtype=bool) & np.isfinite(depth) & (depth > 0)
    if not ok.any():
        return None, sigma
    with warnings.catch_warnings():  # an image with no visible joint in front: filled below
        warnings.simplefilter("ignore", RuntimeWarning)
        per_image = np.nanmedian(np.where(ok, depth, np.nan), axis=1)
    per_image = np.where(np.isfinite(per_image), per_image, float(np.median(depth[ok])))
    Kf = np.asarray(K, dtype=np.float64)
    f_px = 0.5 * (Kf[:, 0, 0] + Kf[:, 1, 1])
    s = max(sigma, min_sigma_px)
    lam = np.array([noise_aware_lambda2(s, float(f), float(d)) for f, d in zip(f_px, per_image, strict=True)])
    return lam, sigma
