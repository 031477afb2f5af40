"""Jumping tracks: countermovement jumps (in place, forward, turning) and repeated small hops."""

from __future__ import annotations

import numpy as np

from gttdata.mocap.procedural._body import Body
from gttdata.mocap.procedural._track import Track, keyframes, smooth_noise

__all__ = ["jump_track"]

_G_MPS2 = 9.81
# Key pose channels, degrees: pelvis tilt, thigh forward tilt in the world, knee flexion, ankle
# dorsiflexion (NaN = keep the foot flat), trunk flexion, shoulder flexion, elbow flexion.
_CHANNELS = ("pelvis", "thigh", "knee", "ankle", "trunk", "shoulder", "elbow")
_NAN = float("nan")


def _stand() -> tuple[float, ...]:
    return (3.0, 1.0, 4.0, _NAN, 2.0, 0.0, 12.0)


def _jump_keys(t0: float, flight_s: float, depth: float, lean: float, tempo: float) -> list[tuple]:
    """Keys of one countermovement jump taking off at ``t0``; ``depth`` in [0.4, 1] scales the crouch."""
    land = t0 + flight_s
    d2 = 0.6 * depth + 0.2
    return [
        (t0 - 0.95 / tempo, *_stand()),
        (t0 - 0.36 / tempo, 5 + 10 * depth, 55 * depth, 90 * depth, _NAN, 20 * depth + lean, -40.0, 20.0),
        (t0, 5.0, -5.0 - 10.0 * lean / 15.0, 5.0, -30.0, 5.0 + lean / 3.0, 115.0, 20.0),
        (t0 + 0.5 * flight_s, 5.0, 15.0 + 10 * depth, 25.0 + 30 * depth, -20.0, 5.0, 150.0, 30.0),
        (land, 5.0, 20.0, 20.0, -15.0, 5.0, 90.0, 30.0),
        (land + 0.22 / tempo, 10 * d2, 40 * d2, 70 * d2, _NAN, 15 * d2, 40.0, 35.0),
        (land + 0.85 / tempo, *_stand()),
    ]


def _hop_keys(t0: float, n_hops: int, period: float, flight_s: float) -> tuple[list[tuple], list[float]]:
    """Keys of ``n_hops`` small two-footed hops on the balls of the feet; also their take-off times."""
    keys = [(t0 - 0.6, *_stand()), (t0 - 0.15, 4.0, 8.0, 25.0, -5.0, 4.0, 15.0, 80.0)]
    takeoffs = []
    for i in range(n_hops):
        ti = t0 + i * period
        takeoffs.append(ti)
        keys += [
            (ti, 3.0, 0.0, 6.0, -28.0, 3.0, 15.0, 80.0),
            (ti + 0.5 * flight_s, 3.0, 4.0, 12.0, -24.0, 3.0, 15.0, 80.0),
            (ti + flight_s, 3.0, 6.0, 12.0, -18.0, 3.0, 15.0, 80.0),
            (ti + 0.5 * (flight_s + period), 4.0, 10.0, 26.0, -6.0, 4.0, 15.0, 80.0),
        ]
    keys.append((t0 + n_hops * period + 0.6, *_stand()))
    return keys, takeoffs


def _apply_keys(track: Track, keys: list[tuple], rng: np.random.Generator) -> None:
    """Interpolate the key channels and write symmetric leg, trunk and arm angles."""
    k = np.asarray(sorted(keys), dtype=np.float64)
    k = k[np.concatenate(([True], np.diff(k[:, 0]) > 1e-3))]
    flat = np.isnan(k[:, 4])
    k[flat, 4] = k[flat, 3] - k[flat, 2]  # ankle = knee - thigh keeps the foot flat
    v = keyframes(track.times_s, k[:, 0], k[:, 1:])
    pelvis, thigh, knee, ankle, trunk, shoulder, elbow = v.T
    track.add("root", 1, pelvis)
    track.add_sides("femur", 1, thigh + pelvis, thigh + pelvis)
    track.add_sides("tibia", 1, knee, knee)
    track.add_sides("foot", 1, ankle, ankle)
    width = rng.uniform(3.0, 8.0)
    track.add_sides("femur", 0, width, width)
    track.add_sides("foot", 0, -width, -width)
    for j in ("lowerback", "upperback", "thorax"):
        track.add(j, 1, trunk / 3.0)
    track.add("upperneck", 1, -0.6 * (trunk + pelvis))
    abd = rng.uniform(6.0, 14.0)
    track.add_sides("humerus", 0, abd, abd)
    track.add_sides("humerus", 1, shoulder, shoulder)
    track.add_sides("radius", 1, elbow, elbow)


def jump_track(
    rng: np.random.Generator, n_frames: int, fps_hz: float, body: Body, *, speed_scale: float | None
) -> tuple[Track, dict]:
    """Track of jumps separated by standing.

    Track of jumps separated by standing: countermovement jumps (in place, forward, with a half
    turn) or a bout of small rope-skipping hops.

    Args:
        rng: Random generator.
        n_frames: Number of frames T.
        fps_hz: Frame rate, Hz.
        body: The subject.
        speed_scale: Tempo of the movement as a multiple of the nominal; drawn when None.

    Returns:
        ``(track, params)``: the track and the jumps drawn (height, distance, turn per jump).
    """
    tempo = speed_scale if speed_scale is not None else rng.uniform(0.85, 1.1)
    track = Track.zeros(n_frames, fps_hz)
    t = track.times_s
    end = t[-1]
    keys: list[tuple] = [(0.0, *_stand()), (end, *_stand())]
    flights: list[tuple[float, float]] = []
    jumps: list[dict] = []
    if rng.uniform() < 0.25 and end > 3.0:
        period = rng.uniform(0.42, 0.55) / tempo
        height = rng.uniform(0.03, 0.08)
        flight = 2.0 * np.sqrt(2.0 * height / _G_MPS2)
        n_hops = int(min(rng.integers(4, 16), (end - 1.6) / period))
        hop_keys, takeoffs = _hop_keys(
            rng.uniform(0.8, max(0.8, end - 0.8 - n_hops * period)), n_hops, period, flight
        )
        keys += hop_keys
        flights = [(ti, ti + flight) for ti in takeoffs]
        jumps.append({"hops": n_hops, "height_m": round(height, 3)})
    else:
        t0 = rng.uniform(1.0, 1.8) / tempo
        while True:
            height = rng.uniform(0.15, 0.45)
            flight = 2.0 * np.sqrt(2.0 * height / _G_MPS2)
            if t0 + flight + 1.0 / tempo > end:
                break
            dist = 0.0 if rng.uniform() < 0.5 else rng.uniform(0.2, 0.9)
            turn = (
                float(rng.choice((-np.pi, -0.5 * np.pi, 0.5 * np.pi, np.pi))) if rng.uniform() < 0.25 else 0.0
            )
            keys += _jump_keys(t0, flight, rng.uniform(0.4, 1.0), 15.0 * dist, tempo)
            flights.append((t0, t0 + flight))
            win = (t > t0 - 0.3) & (t < t0 + flight + 0.3)
            track.flight_vel[win, 0] += dist / flight
            inside = (t > t0) & (t < t0 + flight)
            # sin^2 profile: the heading turns only in the air, with a C1 start and end.
            track.yaw_rate[inside] += 2.0 * turn / flight * np.sin(np.pi * (t[inside] - t0) / flight) ** 2
            jumps.append(
                {"height_m": round(height, 3), "distance_m": round(dist, 3), "turn_rad": round(turn, 3)}
            )
            t0 += flight + rng.uniform(1.9, 3.2) / tempo
    _apply_keys(track, [k for k in keys if 0.0 <= k[0] <= end], rng)
    for a, b in flights:
        track.support[(t > a) & (t < b)] = 0.0
    n = smooth_noise(rng, t, 4, max_hz=0.6)
    track.add("upperneck", 2, 10.0 * n[:, 0])
    track.add("thorax", 2, 3.0 * n[:, 1])
    track.add_sides("humerus", 2, 10.0 + 5.0 * n[:, 2], 10.0 + 5.0 * n[:, 3])
    return track, {"tempo": float(tempo), "jumps": jumps}
