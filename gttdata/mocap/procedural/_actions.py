"""Stub."""

from __future__ import annotations

from gttdata.mocap.procedural._track import Track

__all__ = ["action_track"]


def action_track(rng, kind, n_frames, fps_hz, body, *, speed_scale):
    return Track.zeros(n_frames, fps_hz), {}
