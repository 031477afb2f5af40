"""Stub."""

from __future__ import annotations

from gttdata.mocap.procedural._track import Track

__all__ = ["dance_track"]


def dance_track(rng, kind, n_frames, fps_hz, body, *, speed_scale):
    return Track.zeros(n_frames, fps_hz), {}
