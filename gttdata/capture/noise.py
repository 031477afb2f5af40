"""2-D detection noise: isotropic Gaussian pixel noise plus gross outliers."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["add_detection_noise"]


def add_detection_noise(
    keypoints_px: np.ndarray,
    rng: np.random.Generator,
    *,
    sigma_px: float,
    outlier_rate: float = 0.0,
    outlier_sigma_px: float = 50.0,
    correlate: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Perturb 2-D joints like a keypoint detector would.

    Each joint gets ``N(0, sigma_px^2 I)`` noise; with probability ``outlier_rate`` it instead gets an
    outlier displacement ``N(0, outlier_sigma_px^2 I)`` (a detection on the wrong limb or person).

    Args:
        keypoints_px: Noise-free joints, pixels, shape ``(..., 2)``.
        rng: Random generator.
        sigma_px: Std of the inlier noise per coordinate, pixels.
        outlier_rate: Probability that a joint is an outlier, in ``[0, 1]``.
        outlier_sigma_px: Std of the outlier displacement per coordinate, pixels.
        correlate: Turns the independent standard-normal draws (same shape as ``keypoints_px``) into
            unit-variance noise correlated in time (e.g. :func:`gttdata.capture.realism.correlate_along_streams`);
            None: independent noise.

    Returns:
        ``(noisy_px, is_outlier)``: shapes ``(..., 2)`` float64 and ``(...)`` bool.

    Example:
        >>> px, out = add_detection_noise(np.zeros((2, 3, 2)), np.random.default_rng(0), sigma_px=0.0)
        >>> bool(np.all(px == 0)), int(out.sum())
        (True, 0)
    """
    x = np.asarray(keypoints_px, dtype=np.float64)
    eps = rng.standard_normal(x.shape)
    if correlate is not None:
        eps = correlate(eps)
    is_outlier = rng.random(x.shape[:-1]) < outlier_rate if outlier_rate > 0 else np.zeros(x.shape[:-1], bool)
    scale = np.where(is_outlier, outlier_sigma_px, sigma_px)[..., None]
    return x + scale * eps, is_outlier
