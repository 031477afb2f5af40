"""The Motion value object: joint positions over time in metres, with resampling and edits."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gttdata.skeleton import Skeleton

__all__ = ["Motion"]


@dataclass(frozen=True)
class Motion:
    """Joint trajectories of one subject.

    Args:
        positions: Joint positions in the world frame, metres, shape ``(T, J, 3)``, float64. World is
            z-up (floor at z = 0) for built-in sources; loaders convert y-up files.
        fps_hz: Sampling rate of ``positions`` in Hz.
        skeleton: Topology of the J joints.
        name: Motion name (e.g. ``"01_01"`` or ``"procedural/walk/0003"``).
        provenance: Where it came from (file path, generator and seed, licence note).
    """

    positions: np.ndarray
    fps_hz: float
    skeleton: Skeleton
    name: str = "motion"
    provenance: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions, dtype=np.float64)
        if pos.ndim != 3 or pos.shape[2] != 3:
            raise ValueError(f"motion {self.name!r}: positions must have shape (T, J, 3), got {pos.shape}")
        if pos.shape[0] == 0:
            raise ValueError(f"motion {self.name!r}: positions must have at least 1 frame, got 0")
        if pos.shape[1] != self.skeleton.n_joints:
            raise ValueError(
                f"motion {self.name!r}: positions have {pos.shape[1]} joints, skeleton "
                f"{self.skeleton.name!r} has {self.skeleton.n_joints}"
            )
        if not np.all(np.isfinite(pos)):
            raise ValueError(f"motion {self.name!r}: positions contain NaN or inf")
        if not (np.isfinite(self.fps_hz) and self.fps_hz > 0):
            raise ValueError(f"motion {self.name!r}: fps_hz must be > 0, got {self.fps_hz}")
        object.__setattr__(self, "positions", pos)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.positions.shape[0])

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame, seconds."""
        return (self.n_frames - 1) / self.fps_hz

    @property
    def times_s(self) -> np.ndarray:
        """Frame times in seconds, shape ``(T,)``."""
        return np.arange(self.n_frames) / self.fps_hz

    def sample_at(self, times_s: np.ndarray) -> np.ndarray:
        """Positions at arbitrary times by linear interpolation (clamped at the ends).

        Args:
            times_s: Query times in seconds from the first frame, shape ``(N,)``.

        Returns:
            Positions in metres, shape ``(N, J, 3)``.
        """
        t = np.asarray(times_s, dtype=np.float64) * self.fps_hz
        t = np.clip(t, 0.0, self.n_frames - 1)
        i0 = np.minimum(np.floor(t).astype(np.int64), self.n_frames - 1)
        i1 = np.minimum(i0 + 1, self.n_frames - 1)
        w = (t - i0)[:, None, None]
        return (1.0 - w) * self.positions[i0] + w * self.positions[i1]

    def resample(self, fps_hz: float) -> Motion:
        """The same motion at another frame rate, by linear interpolation."""
        if not (np.isfinite(fps_hz) and fps_hz > 0):
            raise ValueError(f"fps_hz must be > 0, got {fps_hz}")
        n = int(np.floor(self.duration_s * fps_hz + 1e-9)) + 1
        return replace(self, positions=self.sample_at(np.arange(n) / fps_hz), fps_hz=float(fps_hz))

    def trim(self, start_s: float = 0.0, stop_s: float | None = None) -> Motion:
        """Frames with ``start_s <= t <= stop_s`` (seconds from the first frame)."""
        t = self.times_s
        stop = t[-1] if stop_s is None else stop_s
        keep = (t >= start_s - 1e-9) & (t <= stop + 1e-9)
        if not keep.any():
            raise ValueError(f"trim({start_s}, {stop_s}) keeps no frame of {self.duration_s:.3f} s motion")
        return replace(self, positions=self.positions[keep])

    def mirror(self, axis: int = 1) -> Motion:
        """Left/right mirror: reflect coordinate ``axis`` and swap left and right joints."""
        pos = self.positions[:, self.skeleton.flip_index()].copy()
        pos[..., axis] *= -1.0
        return replace(self, positions=pos, name=f"{self.name}+mirror")

    def scale_bones(self, factor: float | np.ndarray) -> Motion:
        """Rescale bone lengths, keeping the root trajectory and every bone's direction.

        Args:
            factor: One factor, or one per joint (the bone ending at that joint), shape ``(J,)``.
        """
        f = np.broadcast_to(np.asarray(factor, dtype=np.float64), (self.skeleton.n_joints,))
        out = self.positions.copy()
        for j in self.skeleton.topological_order:
            p = self.skeleton.parents[j]
            if p >= 0:
                out[:, j] = out[:, p] + f[j] * (self.positions[:, j] - self.positions[:, p])
        return replace(self, positions=out)

    def bone_lengths(self) -> np.ndarray:
        """Bone lengths per frame in metres, shape ``(T, n_bones)``, in ``skeleton.bones`` order."""
        b = self.skeleton.bones
        return np.linalg.norm(self.positions[:, b[:, 0]] - self.positions[:, b[:, 1]], axis=-1)
