"""Stub."""

from __future__ import annotations

from gttdata.mocap.procedural._track import Track

__all__ = ["mixed_track"]


def mixed_track(rng, parts, n_frames, fps_hz, body, *, speed_scale, build):
    return Track.zeros(n_frames, fps_hz), {}
