"""Each camera's frame rate, checked or estimated from the images: the rate under which its stream meets the others.

A camera's local times are ``k / rate``; a wrong rate stretches its stream in time, and its rays then meet
another camera's rays at one moment only, not all along the recording. For each camera, candidate rates
(the rate it was given, the common camera rates and their ratios to a reference camera's rate) are scored
by the pairwise ray-meeting consensus against the reference camera (:func:`gttnet.sync.pairs.pair_offset`);
the best-scoring rate is kept where it explains the images clearly better than the given (or, without a
given rate, the reference's) rate.

Only rates relative to each other are observable from the motion; the absolute scale is an assumption:
the reference camera's given rate, else the common rate (nearest 30 Hz) that puts the most cameras on
common rates.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.sync.pairs import Stream, camera_streams, pair_errors, pair_offset

__all__ = [
    "ACCEPT_NOISE",
    "ACCEPT_PX",
    "CLEARLY_BETTER",
    "COMMON_RATES_HZ",
    "MIN_USABLE_IMAGES",
    "blind_cameras",
    "check_rates",
    "rate_warnings",
    "time_warnings",
]

log = logging.getLogger(__name__)

#: Frame rates cameras commonly run at, Hz (NTSC rates 23.976, 29.97... lie within 0.1 % of these: the clock
#: drift fit, not the rate choice, absorbs that difference).
COMMON_RATES_HZ = (24.0, 25.0, 30.0, 48.0, 50.0, 60.0, 90.0, 100.0, 120.0)
#: A rate replaces the given one only where its consensus score is this many times the given rate's.
CLEARLY_BETTER = 1.25
#: A camera with fewer images that see at least two joints carries no timing information.
MIN_USABLE_IMAGES = 3
#: Candidate rates lie within this factor of the rate the cameras' image counts suggest.
_COUNT_FACTOR = 3.0
#: A given rate stands without a search where its median ray miss against the reference camera is within
#: this many times the capture's noise estimate plus :data:`ACCEPT_PX` (right rates leave 0.65-0.75 times the
#: noise on the sync recipe at 1, 2 and 5 px; a wrong one 1.3 times and more).
ACCEPT_NOISE = 1.0
ACCEPT_PX = 0.3
#: Rates within this relative difference are the same rate.
_SAME = 0.003
#: Rate estimation uses each camera's first seconds only (the offset search is linear in the span).
_ESTIMATE_SPAN_S = 20.0


def blind_cameras(obs: Observations) -> dict[int, str]:
    """Cameras whose images carry no information for their clock, with the reason.

    A camera with fewer than :data:`MIN_USABLE_IMAGES` images that see at least two joints (every detection
    below the confidence threshold, NaN scores, a NaN distortion coefficient or no detection at all end
    there: such joints are missing) is blind.

    Returns:
        ``{camera id: reason}``, empty when every camera sees the subject.
    """
    vis = np.asarray(obs.visible, dtype=bool)
    cam = np.asarray(obs.cam_id)
    out: dict[int, str] = {}
    for c in np.unique(cam):
        n = int((cam == c).sum())
        usable = int((vis[cam == c].sum(axis=1) >= 2).sum())
        if n < MIN_USABLE_IMAGES:
            out[int(c)] = f"{n} image(s), a clock needs at least {MIN_USABLE_IMAGES}"
        elif usable < MIN_USABLE_IMAGES:
            out[int(c)] = (
                f"no usable detection ({usable} of {n} images see two joints or more: every detection below "
                "the confidence threshold, NaN scores or NaN distortion)"
            )
    return out


def _candidates(ref_hz: float, prior_hz: float, given_hz: float) -> np.ndarray:
    """Rates to try for one camera: ``ref_hz`` times ratios of common rates, near ``prior_hz``."""
    ratios = {a / b for a in COMMON_RATES_HZ for b in COMMON_RATES_HZ}
    cand = sorted(
        r * ref_hz for r in ratios if prior_hz / _COUNT_FACTOR <= r * ref_hz <= prior_hz * _COUNT_FACTOR
    )
    kept: list[float] = []
    for r in cand:  # merge rates within 0.3 % of each other
        if not kept or r > kept[-1] * (1.0 + _SAME):
            kept.append(r)
    for r in (ref_hz, given_hz):  # the count-based rate only centres the range: it is no camera rate
        if not any(abs(k / r - 1.0) < _SAME for k in kept):
            kept.append(r)
    return np.array(sorted(kept))


def _fit(ref: Stream, st: Stream, f_px: float, cap: float) -> tuple[float, float]:
    """``(consensus score, median ray miss px)`` of ``st`` against ``ref`` at their best shift."""
    delta, score, _ = pair_offset(ref, st, cap=cap)
    err, ok = pair_errors(ref, st, np.arange(ref.tau.shape[0]), ref.tau + delta)
    return score, float(np.median(err[ok]) * f_px) if ok.any() else float("inf")


def _rescaled(st: Stream, factor: float) -> Stream:
    """``st`` with its local times multiplied by ``factor`` (another rate)."""
    return replace(st, tau=st.tau * factor, max_gap_s=st.max_gap_s * factor)


def _thinned(st: Stream, n: int) -> Stream:
    """At most ``n`` evenly spread frames of ``st``, for use as the first stream of a pair only."""
    if st.tau.shape[0] <= n:
        return st
    k = np.unique(np.linspace(0, st.tau.shape[0] - 1, n).round().astype(int))
    return replace(
        st, images=st.images[k], tau=st.tau[k], rays=st.rays[:, k], centers=st.centers[:, k], ok=st.ok[k],
        var=st.var[k], cov=st.cov[k],
    )  # fmt: skip


def _absolute_scale(rel: Mapping[int, float]) -> float:
    """Rate of relative rate 1 that puts the most cameras on common rates (ties: nearest 30 Hz)."""
    best, best_key = 1.0, (-1, float("inf"))
    for target in COMMON_RATES_HZ:
        s = target / max(rel.values())
        hits = sum(any(abs(r * s / c - 1.0) < _SAME for c in COMMON_RATES_HZ) for r in rel.values())
        key = (hits, abs(np.log(s / 30.0)))
        if key[0] > best_key[0] or (key[0] == best_key[0] and key[1] < best_key[1]):
            best, best_key = s, key
    return best


def _given_scale(rel: Mapping[int, float], rates: Mapping[int, float], ref: int) -> float:
    """Rate of relative rate 1 that the most cameras' given rates agree with (ties: the reference's)."""
    votes = {c: rates[c] / rel[c] for c in rel}
    support = {c: sum(abs(votes[k] / votes[c] - 1.0) < _SAME for k in votes) for c in votes}
    top = max(support.values())
    return votes[ref] if support[ref] == top else votes[min(c for c in votes if support[c] == top)]


def _relative_rate(
    ref: Stream, st: Stream, *, ref_hz: float, base_hz: float, keep_hz: float, f_px: float, cap: float,
    accept_px: float | None,
) -> tuple[float, dict]:  # fmt: skip
    """A camera's rate in the reference's units: ``keep_hz`` unless another explains the images clearly better.

    ``keep_hz`` is tried first; where its median miss is within ``accept_px``, it is kept without a search.
    Else every candidate is scored on a thinned reference stream, and the three best again on the whole.
    """
    kept = _fit(ref, _rescaled(st, base_hz / keep_hz), f_px, cap)
    row: dict = {"given_miss_px": kept[1], "searched": False}
    if accept_px is not None and kept[1] <= accept_px:
        return keep_hz, {**row, "estimated_hz": keep_hz, "miss_px": kept[1]}
    prior = ref_hz * st.tau.shape[0] / ref.tau.shape[0]  # right when both filmed the same span
    thin = _thinned(ref, 32)
    coarse = {}
    for r in _candidates(ref_hz, prior, keep_hz):
        try:
            coarse[float(r)] = _fit(thin, _rescaled(st, base_hz / r), f_px, cap)[0]
        except GttNetError:
            continue
    top = sorted(coarse, key=lambda r: -coarse[r])[:3]
    trials = {r: _fit(ref, _rescaled(st, base_hz / r), f_px, cap) for r in top}
    trials[keep_hz] = kept
    best = max(trials, key=lambda r: trials[r][0])
    clearly = abs(best / keep_hz - 1.0) > _SAME and trials[best][0] > CLEARLY_BETTER * max(kept[0], 1e-9)
    use = best if clearly else keep_hz
    return use, {**row, "searched": True, "estimated_hz": best, "miss_px": trials[use][1]}


def check_rates(
    obs: Observations,
    tau: np.ndarray,
    rates: Mapping[int, float],
    *,
    given: bool,
    f_px: float,
    cap: float,
    noise_px: float | None = None,
    kernel_frames: float = 1.0,
) -> tuple[dict[int, float], np.ndarray, dict]:
    """Check the cameras' frame rates against the images, or estimate them.

    Each camera is aligned with a reference camera (the one with the most images) under its given rate
    (without given rates: the reference's). Where the median ray miss is within :data:`ACCEPT_NOISE` times the
    noise estimate (plus :data:`ACCEPT_PX`), the rate stands; else candidate rates are searched and the best
    replaces it where its consensus is :data:`CLEARLY_BETTER` times the given rate's. The absolute scale is
    the one most given rates agree with (so a wrong reference is found too), or without given rates the one
    that puts the most cameras on :data:`COMMON_RATES_HZ`.

    Args:
        obs: Observations with each camera's frame order; cameras with a clock to recover.
        tau: Each image's local time under ``rates``, seconds, shape ``(N,)``.
        rates: The rate of every camera the local times assume, Hz (given, measured or assumed).
        given: Whether ``rates`` were given (declared or measured); False: assumed, every camera estimated.
        f_px: Focal length that turns ray misses into pixels.
        cap: Ray misses at or above this many radians count as disagreement.
        noise_px: The capture's 2-D noise estimate, pixels (None: every camera is searched).
        kernel_frames: Temporal kernel of the streams, frames.

    Returns:
        ``(rates, tau, info)``: the rates kept, Hz, the local times under them, shape ``(N,)``, and ``info``
        with ``reference_camera``, ``assumed_hz`` (the reference's absolute rate), ``given``, ``noise_px``
        and per camera (``cameras[str(id)]``) ``given_hz`` (None when assumed), ``estimated_hz``,
        ``used_hz``, ``relative`` (rate over the reference's), ``miss_px`` (median ray miss against the
        reference at the rate used, pixels), ``given_miss_px`` (at the given rate), ``searched`` and
        ``changed`` (the rate used is not the given one).
    """
    cam = np.asarray(obs.cam_id)
    cams = [int(c) for c in np.unique(cam)]
    first = np.array([float(tau[cam == c].min()) for c in cams])[np.searchsorted(cams, cam)]
    idx = np.flatnonzero(tau - first <= _ESTIMATE_SPAN_S)
    streams = {s.camera: s for s in camera_streams(obs, tau, rates, kernel_frames, idx)}
    ref = max(cams, key=lambda c: (streams[c].tau.shape[0], -c))
    ref_hz = float(rates[ref])
    accept = None if noise_px is None else ACCEPT_NOISE * noise_px + ACCEPT_PX
    rel: dict[int, float] = {ref: 1.0}
    rows: dict[str, dict] = {str(ref): {"miss_px": None, "given_miss_px": None, "searched": False}}
    for c in cams:
        if c == ref:
            continue
        keep = float(rates[c]) if given else ref_hz
        use, row = _relative_rate(
            streams[ref], streams[c], ref_hz=ref_hz, base_hz=float(rates[c]), keep_hz=keep, f_px=f_px,
            cap=cap, accept_px=accept,
        )  # fmt: skip
        rel[c] = use / ref_hz
        rows[str(c)] = {**row, "estimated_hz": row["estimated_hz"] / ref_hz}
    rows[str(ref)]["estimated_hz"] = 1.0
    scale = _given_scale(rel, rates, ref) if given else _absolute_scale(rel)
    out = {c: rel[c] * scale for c in cams}
    for c in cams:
        row = rows[str(c)]
        row.update(
            {
                "given_hz": float(rates[c]) if given else None,
                "estimated_hz": float(row["estimated_hz"] * scale),
                "used_hz": float(out[c]),
                "relative": float(rel[c]),
                "changed": bool(given and abs(out[c] / rates[c] - 1.0) > _SAME),
            }
        )
    rows = {str(c): rows[str(c)] for c in cams}  # by camera id
    new_tau = tau * np.array([rates[int(k)] / out[int(k)] for k in cam])
    info = {
        "reference_camera": ref, "assumed_hz": float(out[ref]), "given": given, "noise_px": noise_px,
        "cameras": rows,
    }  # fmt: skip
    return out, new_tau, info


def rate_warnings(info: Mapping, names: Mapping[int, str] | None = None) -> list[str]:
    """The user-facing warnings of a rate check (``info`` of :func:`check_rates`), cameras named by ``names``.

    Example:
        >>> rate_warnings({"given": True, "reference_camera": 0, "assumed_hz": 30.0, "cameras": {
        ...     "0": {"given_hz": 30.0, "used_hz": 30.0, "changed": False},
        ...     "1": {"given_hz": 30.0, "used_hz": 60.0, "estimated_hz": 60.0, "changed": True,
        ...           "miss_px": 1.1, "given_miss_px": 7.8}}}, {1: "side"})
        ['camera side: the given 30 Hz does not explain the images (median ray miss 7.8 px against 1.1 px at 60 Hz); likely 60 Hz, used instead']
    """

    def name(c: int) -> str:
        return names.get(c, str(c)) if names is not None else str(c)

    rows = info.get("cameras", {})
    out = []
    if not info.get("given", True):
        ref = int(info["reference_camera"])
        rates = ", ".join(f"{name(int(c))} {r['used_hz']:.4g}" for c, r in rows.items())
        out.append(
            f"no frame rate given: rates estimated from the images, relative to camera {name(ref)} (assumed "
            f"{info['assumed_hz']:.4g} Hz; only relative rates are observable): {rates} Hz; pass --fps to set them"
        )
        return out
    noise = info.get("noise_px")
    of_noise = "" if noise is None else f", noise {noise:.1f} px"
    for c, r in rows.items():
        if not r.get("changed"):
            continue
        if r.get("given_miss_px") is None:  # the reference camera: its rate disagrees with the others'
            why = "disagrees with the other cameras' given rates and the images"
        else:
            why = (
                f"does not explain the images (median ray miss {r['given_miss_px']:.1f} px against "
                f"{r['miss_px']:.1f} px at {r['used_hz']:.4g} Hz{of_noise})"
            )
        out.append(
            f"camera {name(int(c))}: the given {r['given_hz']:.4g} Hz {why}; likely {r['used_hz']:.4g} Hz, used instead"
        )
    return out


def time_warnings(info: Mapping, names: Mapping[int, str] | None = None) -> list[str]:
    """The ``warning:`` lines of a timed reconstruction's ``info`` (``frame_rates``, ``cameras_left_out``).

    Cameras are named by ``names`` (camera id -> name; default: the id).
    """
    left = info.get("cameras_left_out") or {}
    lines = [
        f"camera {names.get(int(c), c) if names is not None else c} left out of the timed solve "
        f"(no clock, its poses NaN): {why}"
        for c, why in left.items()
    ]
    return lines + rate_warnings(info.get("frame_rates") or {}, names)
