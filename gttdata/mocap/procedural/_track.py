"""Kinematic track of one procedural motion: anatomical joint angles, yaw rate and ground support."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import PchipInterpolator

from gttdata.mocap.procedural._body import JOINT, SIGNS

__all__ = ["Track", "hann_smooth", "keyframes", "segment_weights", "smooth_noise", "smootherstep"]


@dataclass
class Track:
    """Everything a kind generator decides; the root path and world positions are derived from it.

    Args:
        fps_hz: Frame rate, Hz.
        angles: Anatomical joint angles in radians, shape ``(T, J, 3)``: (abduction or lateral bend
            to the left, flexion, internal rotation or twist to the left); mapped to local rotation
            channels by :data:`SIGNS`. The root row is the pelvis orientation relative to the heading.
        yaw_rate: Heading rate about the world z axis, rad/s, shape ``(T,)``.
        support: 1 where the feet carry the body, 0 in flight (running, jumping), shape ``(T,)``.
        flight_vel: Extra horizontal root velocity during flight in the heading frame (x forward,
            y left), m/s, shape ``(T, 2)``.
        contact: Load carried by each foot joint of ``FOOT_JOINTS`` (lfoot, ltoes, rfoot, rtoes)
            where the generator knows it (gait phases), shape ``(T, 4)``; rows sum to 1 or 0.
        contact_mix: How far to trust ``contact`` over the lowest-foot rule, in [0, 1], shape ``(T,)``.
    """

    fps_hz: float
    angles: np.ndarray
    yaw_rate: np.ndarray
    support: np.ndarray
    flight_vel: np.ndarray
    contact: np.ndarray
    contact_mix: np.ndarray

    @classmethod
    def zeros(cls, n_frames: int, fps_hz: float) -> Track:
        """A motionless standing track of ``n_frames`` frames."""
        return cls(
            fps_hz=fps_hz,
            angles=np.zeros((n_frames, len(JOINT), 3)),
            yaw_rate=np.zeros(n_frames),
            support=np.ones(n_frames),
            flight_vel=np.zeros((n_frames, 2)),
            contact=np.zeros((n_frames, 4)),
            contact_mix=np.zeros(n_frames),
        )

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.angles.shape[0])

    @property
    def times_s(self) -> np.ndarray:
        """Frame times from 0, seconds, shape ``(T,)``."""
        return np.arange(self.n_frames) / self.fps_hz

    def add(self, joint: str, axis: int, values_deg: np.ndarray | float) -> None:
        """Add an anatomical angle in degrees to ``joint`` (``axis`` 0 abduction, 1 flexion, 2 rotation)."""
        self.angles[:, JOINT[joint], axis] += np.deg2rad(values_deg)

    def add_sides(
        self, joint: str, axis: int, left_deg: np.ndarray | float, right_deg: np.ndarray | float
    ) -> None:
        """Add angles to the left and right instances of a limb joint named without its side letter."""
        self.add("l" + joint, axis, left_deg)
        self.add("r" + joint, axis, right_deg)

    def local_channels(self) -> np.ndarray:
        """Local rotation channels for forward kinematics, radians, shape ``(T, J, 3)``."""
        return self.angles * SIGNS


def smooth_noise(
    rng: np.random.Generator, times_s: np.ndarray, n: int, *, max_hz: float, n_terms: int = 4
) -> np.ndarray:
    """Band-limited noise: a sum of random sinusoids below ``max_hz``, unit RMS per channel.

    Args:
        rng: Random generator.
        times_s: Sample times, seconds, shape ``(T,)``.
        n: Number of independent channels.
        max_hz: Highest frequency, Hz.
        n_terms: Sinusoids per channel.

    Returns:
        Noise, shape ``(T, n)``; infinitely differentiable, so it adds no velocity spikes.
    """
    freq = rng.uniform(0.05, max_hz, size=(n_terms, n))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(n_terms, n))
    amp = rng.standard_normal((n_terms, n))
    amp *= np.sqrt(2.0 / np.maximum((amp**2).sum(axis=0, keepdims=True), 1e-12))
    return np.einsum("kn,tkn->tn", amp, np.sin(2.0 * np.pi * freq * times_s[:, None, None] + phase))


def smootherstep(x: np.ndarray) -> np.ndarray:
    """Quintic ramp from 0 (x <= 0) to 1 (x >= 1) with zero first and second derivatives at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def keyframes(times_s: np.ndarray, key_times_s: np.ndarray, key_values: np.ndarray) -> np.ndarray:
    """Shape-preserving (PCHIP, C1) interpolation of keyframes, held constant outside the keys.

    Args:
        times_s: Query times, seconds, shape ``(T,)``.
        key_times_s: Strictly increasing key times, seconds, shape ``(K,)``.
        key_values: Key values, shape ``(K, ...)``.

    Returns:
        Interpolated values, shape ``(T, ...)``.
    """
    t = np.clip(times_s, key_times_s[0], key_times_s[-1])
    return PchipInterpolator(key_times_s, key_values, axis=0)(t)


def segment_weights(t: np.ndarray, bounds: list[float], fade_s: float) -> np.ndarray:
    """Partition of unity over segments ``[bounds[i], bounds[i+1])`` with C2 cross-fades, ``(T, S)``."""
    ramps = [smootherstep((t - b + 0.5 * fade_s) / fade_s) for b in bounds[1:-1]]
    up = [np.ones_like(t), *ramps]
    down = [*(1.0 - r for r in ramps), np.ones_like(t)]
    return np.stack([a * b for a, b in zip(up, down, strict=True)], axis=1)


def hann_smooth(x: np.ndarray, half: int) -> np.ndarray:
    """Hann-window moving average along axis 0 (edges padded with the end values).

    Args:
        x: Signal, shape ``(T, C)``.
        half: Half-width of the window in samples; ``< 1`` returns ``x`` unchanged.

    Returns:
        Smoothed signal, shape ``(T, C)``.
    """
    if half < 1:
        return x
    win = np.hanning(2 * half + 3)[1:-1]
    win /= win.sum()
    pad = np.pad(x, ((half, half), (0, 0)), mode="edge")
    return np.stack([np.convolve(pad[:, k], win, mode="valid") for k in range(x.shape[1])], axis=1)
