"""Clock recovery from the skeletons themselves: epipolar alignment of every pair of camera streams.

Two calibrated cameras that film the same instant see rays that meet at every joint; a stream shifted in
time sees rays that miss. For each pair of cameras the offset that makes one stream's rays meet the other
stream's rays, interpolated at the same instant, is found by a coarse-to-fine search; the pairwise
offsets are fused into one offset per camera by a robust least-squares fit over the camera graph; then
all offsets (and, over long recordings, drifts) are refined together by a robust non-linear least-squares
fit of every ray-meeting residual, whose Jacobian gives each offset's uncertainty.

Cost: for each of the ``V (V - 1) / 2`` camera pairs, the coarse search evaluates at most
``max_coarse_images`` images at every coarse shift (a fixed cost per pair times the searched range),
the fine search and the refinement evaluate every image a fixed number of times: linear in the number
of images N for a fixed search range, never an N x N matrix. The searched range, though, is the whole
recording unless ``max_offset_s`` bounds it, and so is the refinement's every image: measured 1.1 s at
1,440 images, 7 s at 7,200 and 48 s at 24,000. Long recordings (streams spanning more than
:data:`PIECEWISE_FROM_S`) are therefore recovered piecewise (:func:`recover_clocks`, ``piecewise``): the
full search on each camera's first :data:`SEGMENT_S` seconds only, then a local search around those
offsets in :data:`N_WINDOWS` windows of :data:`WINDOW_S` seconds spread over the whole recording, whose
shifts give every camera's offset and drift by a robust linear fit, refined on the windows' images
together. The cost is then a fixed amount of search plus work linear in N (placing the images), and
drift over the whole recording is followed: the windows at its end see what the start cannot.

The pair search is :mod:`gttnet.sync.pairs`, the fusion over the camera graph :mod:`gttnet.sync.fusion`.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.sync.clocks import Clocks, local_times, per_camera_rates
from gttnet.sync.fusion import fuse_clocks, fuse_offsets
from gttnet.sync.pairs import Stream, camera_streams, pair_errors, pair_offset, ray_meeting_error
from gttnet.sync.rates import blind_cameras, time_warnings
from gttnet.sync.rates import check_rates as rate_check

__all__ = [
    "N_WINDOWS",
    "PIECEWISE_FROM_S",
    "SEGMENT_S",
    "WINDOW_S",
    "Stream",
    "pair_offset",
    "ray_meeting_error",
    "recover_clocks",
]

log = logging.getLogger(__name__)

#: ``piecewise=None`` recovers recordings whose longest stream spans more than this piecewise, seconds.
PIECEWISE_FROM_S = 40.0
#: Piecewise recovery: local seconds at each camera's start that get the full offset search.
SEGMENT_S = 20.0
#: Piecewise recovery: windows spread over the whole recording, and their length in seconds.
N_WINDOWS = 8
WINDOW_S = 5.0
#: Piecewise recovery: shifts searched around the first offsets: this many seconds, plus this many
#: seconds per second elapsed since the start (a clock-rate difference of 500 ppm).
_SEARCH_S = 0.25
_SEARCH_PER_S = 5e-4


class _Refiner:
    """Every ordered pair's ray-meeting residuals as a function of the clock parameters."""

    def __init__(self, streams: list[Stream], f_px: float, estimate_drift: bool) -> None:
        self.s, self.f, self.drift = streams, f_px, estimate_drift
        self.pairs = [(i, j) for i in range(len(streams)) for j in range(len(streams)) if i != j]
        self.n_valid = 0

    def unpack(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        v = len(self.s)
        o = np.concatenate([[0.0], p[: v - 1]])
        d = np.concatenate([[0.0], p[v - 1 :]]) if self.drift else np.zeros(v)
        return o, d

    def residuals(self, p: np.ndarray, only: int | None = None, base: np.ndarray | None = None) -> np.ndarray:
        """All residuals, or only those of the pairs that involve one camera.

        All residuals; with ``only`` (a camera) and ``base`` (the residuals at other parameters), only the
        pairs that involve camera ``only`` are recomputed (a Jacobian column).
        """
        o, d = self.unpack(p)
        out, nv, pos = [], 0, 0
        for i, j in self.pairs:
            a, b = self.s[i], self.s[j]
            size = a.tau.shape[0] * a.rays.shape[2]
            if only is not None and only not in (i, j):
                assert base is not None  # `only` comes with the residuals at the other parameters
                out.append(base[pos : pos + size])
                pos += size
                continue
            t = o[i] + (1.0 + 1e-6 * d[i]) * a.tau
            tq = (t - o[j]) / (1.0 + 1e-6 * d[j])
            err, ok = pair_errors(a, b, np.arange(a.tau.shape[0]), tq)
            out.append((err * self.f).ravel())
            nv += int(ok.sum())
            pos += size
        if only is None:
            self.n_valid = nv
        return np.concatenate(out)


def _recover(
    streams: list[Stream],
    *,
    f_px: float,
    cap: float,
    max_offset_s: float | None,
    f_scale_px: float,
    refine: bool,
    period: float,
    n_joints: int,
    drift: bool,
    init: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Offsets and drifts (camera 0 the gauge), their uncertainty and diagnostics, from whole streams.

    Without ``init``, the pairwise search over every camera pair fused over the camera graph starts the
    refinement; with ``init = (offsets, drifts_ppm)`` the refinement starts there.
    """
    v = len(streams)
    info: dict = {"front_end": "epipolar", "estimate_drift": drift, "refined": refine}
    if init is None:
        pairs, pair_info = [], []
        for i in range(v):
            for j in range(i + 1, v):
                delta, score, ratio = pair_offset(streams[i], streams[j], cap=cap, max_offset_s=max_offset_s)
                pairs.append((i, j, delta, score))  # o_i + tau_i = o_j + tau_i + delta: o_i - o_j = delta
                pair_info.append(
                    {
                        "cameras": [streams[i].camera, streams[j].camera],
                        "shift_s": delta,
                        "score": score,
                        "peak_ratio": ratio,
                    }
                )
        info["pairs"] = pair_info
        o, d = fuse_offsets(v, pairs, scale=period), np.zeros(v)
    else:
        o, d = (np.asarray(a, dtype=np.float64).copy() for a in init)
    std = np.full(v, np.nan)
    if not refine:
        return o, d, std, info
    ref = _Refiner(streams, f_px, drift)
    p0 = np.concatenate([o[1:], d[1:]]) if drift else o[1:].copy()
    steps = np.concatenate([np.full(v - 1, 0.05 * period), np.full(v - 1 if drift else 0, 2.0)])
    cache: dict = {}

    def fun(p):
        key = p.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = ref.residuals(p)
        return cache[key]

    def jac(p):
        f0 = fun(p)
        cam = [1 + q % (v - 1) for q in range(p.size)]  # parameter q moves camera cam[q]'s clock
        cols = [
            (ref.residuals(p + steps[q] * np.eye(p.size)[q], only=cam[q], base=f0) - f0) / steps[q]
            for q in range(p.size)
        ]
        return np.stack(cols, axis=1)

    x_scale = np.concatenate([np.full(v - 1, period), np.full(v - 1 if drift else 0, 100.0)])
    from scipy.optimize import least_squares  # imported on use (0.1-0.2 s of start-up)

    res = least_squares(fun, p0, jac=jac, loss="soft_l1", f_scale=f_scale_px, x_scale=x_scale, max_nfev=50)
    o, d = ref.unpack(res.x)
    ref.residuals(res.x)
    dof = max(ref.n_valid - res.x.size, 1)
    J = res.jac
    try:
        cov = np.linalg.inv(J.T @ J) * (2.0 * res.cost / dof)
    except np.linalg.LinAlgError:
        cov = np.full((res.x.size, res.x.size), np.nan)
    # Joints of one image share its timing error: count images, not joints, as independent samples.
    cov *= n_joints
    full = np.zeros((v, v))
    full[1:, 1:] = cov[: v - 1, : v - 1]
    centre = np.eye(v) - 1.0 / v
    std = np.sqrt(np.clip(np.diag(centre @ full @ centre.T), 0.0, None))
    info.update(
        {"nfev": int(res.nfev), "rms_px": float(np.sqrt(2.0 * res.cost / dof)), "n_residuals": ref.n_valid}
    )
    return o, d, std, info


def _recover_piecewise(
    obs: Observations,
    tau: np.ndarray,
    rates: Mapping[int, float],
    kernel_frames: float,
    *,
    drift: bool,
    **opts: Any,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """:func:`_recover` for a long recording: first segment, windows over the whole, refinement on those.

    1. The full pairwise search on every camera's first ``SEGMENT_S`` local seconds (at least three
       times ``max_offset_s``) gives first offsets (no drift).
    2. ``N_WINDOWS`` windows of ``WINDOW_S`` seconds, evenly spread over the time every camera records
       (placed by the first offsets): in each, every camera pair's shift is searched around its
       prediction (``+-`` :data:`_SEARCH_S` plus :data:`_SEARCH_PER_S` per second elapsed); all shifts
       give offsets and drifts by a Huber fit (:func:`_fuse_clocks`).
    3. The joint refinement of :func:`_recover` on the windows' images together, from that fit.
    """
    cam = np.asarray(obs.cam_id)
    cams = np.unique(cam)
    first = np.zeros(cam.shape[0])
    for c in cams:
        first[cam == c] = tau[cam == c].min()
    max_offset_s = opts["max_offset_s"]
    seg_s = SEGMENT_S if max_offset_s is None else max(SEGMENT_S, 3.0 * float(max_offset_s))
    seg = np.flatnonzero(tau - first <= seg_s)
    o0, _, _, seg_info = _recover(
        camera_streams(obs, tau, rates, kernel_frames, seg), **{**opts, "drift": False, "refine": True}
    )
    pos = np.searchsorted(cams, cam)
    t = o0[pos] + tau  # first placement in time
    start = max(float(t[cam == c].min()) for c in cams)
    end = min(float(t[cam == c].max()) for c in cams)
    period = opts["period"]
    starts = np.linspace(start, max(end - WINDOW_S, start), N_WINDOWS)
    eqs: list[tuple[int, int, float, float, float]] = []
    wins: list[np.ndarray] = []
    win_info = []
    for t0 in starts:
        search = _SEARCH_S + _SEARCH_PER_S * float(t0 - start)
        margin = search + 3.0 * period
        idx = np.flatnonzero((t >= t0 - margin) & (t <= t0 + WINDOW_S + margin))
        try:
            ws = camera_streams(obs, tau, rates, kernel_frames, idx)
        except GttNetError as exc:  # a camera with too few frames here
            log.debug("clock window at %.1f s skipped (%s)", t0, exc)
            continue
        if len(ws) != cams.size:
            continue
        wins.append(idx)
        for i in range(cams.size):
            for j in range(i + 1, cams.size):
                try:
                    delta, score, ratio = pair_offset(
                        ws[i], ws[j], cap=opts["cap"], max_offset_s=search, around_s=float(o0[i] - o0[j])
                    )
                except GttNetError:
                    continue
                eqs.append((i, j, float(np.median(ws[i].tau)), delta, score))
                win_info.append(
                    {"start_s": float(t0), "cameras": [int(cams[i]), int(cams[j])], "shift_s": delta,
                     "score": score, "peak_ratio": ratio}
                )  # fmt: skip
    if not eqs:
        raise GttNetError("clock recovery: no window of the recording is seen by two cameras")
    o, d = fuse_clocks(cams.size, eqs, scale=period, drift=drift)
    union = np.unique(np.concatenate(wins))
    o, d, std, info = _recover(
        camera_streams(obs, tau, rates, kernel_frames, union), drift=drift, init=(o, d), **opts
    )
    info["pairs"] = seg_info.get("pairs", [])
    info["piecewise"] = {
        "segment_s": seg_s,
        "segment_images": int(seg.size),
        "windows": len(wins),
        "window_s": WINDOW_S,
        "window_images": int(union.size),
        "window_pairs": win_info,
    }
    return o, d, std, info


def _leave_out_blind(
    obs: Observations, frame_times_s: np.ndarray | None
) -> tuple[Observations, np.ndarray | None, dict[int, str]]:
    """``obs`` (and its frame times) without the cameras that :func:`blind_cameras` finds, and those.

    Raises:
        GttNetError: Fewer than two cameras see the subject.
    """
    blind = blind_cameras(obs)
    if not blind:
        return obs, frame_times_s, {}
    keep = np.flatnonzero(~np.isin(obs.cam_id, list(blind)))
    seeing = np.unique(obs.cam_id[keep]).size
    if seeing < 2:
        why = "; ".join(f"camera {c}: {reason}" for c, reason in blind.items())
        raise GttNetError(f"clock recovery needs two cameras with a usable stream, {seeing} left ({why})")
    ft = None if frame_times_s is None else np.asarray(frame_times_s)[keep]
    return obs.take(keep), ft, blind


def _noise_px(obs: Observations, tau: np.ndarray) -> float | None:
    """The capture's 2-D noise, pixels (:func:`gttnet.geometry.noise.stream_noise_px`), None if unmeasurable."""
    from gttnet.geometry.noise import stream_noise_px

    si = obs.stream_index
    if si is None:  # frame times only: rank within each stream
        si = np.empty(obs.n_images, dtype=np.int64)
        for c in np.unique(obs.cam_id):
            sel = np.flatnonzero(obs.cam_id == c)
            si[sel[np.argsort(tau[sel], kind="stable")]] = np.arange(sel.size)
    return stream_noise_px(obs.keypoints_px, obs.visible, obs.cam_id, si)


def recover_clocks(
    obs: Observations,
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None = None,
    frame_times_s: np.ndarray | None = None,
    max_offset_s: float | None = None,
    estimate_drift: bool | None = None,
    kernel_frames: float = 1.0,
    cap_px: float = 15.0,
    f_scale_px: float = 3.0,
    refine: bool = True,
    piecewise: bool | None = None,
    check_rates: bool = True,
) -> Clocks:
    """Recover every camera's clock from the 2-D joints alone (no timestamps are read).

    Args:
        obs: Observations with each camera's frame order (``partial``, or ``full`` whose timestamps are
            ignored), or any sequencing with ``frame_times_s``. Cameras are calibrated (``K``,
            ``cam_from_world``); ``cam_id`` values need not be contiguous and their order does not matter.
        fps: Nominal frame rate per camera (see :func:`gttnet.sync.clocks.per_camera_rates`); local frame
            times are ``stream_index / fps`` unless ``frame_times_s`` is given or the observations carry
            ``stream_time_s`` (then, without ``fps``, each rate is the inverse median frame interval).
        frame_times_s: Per-image time on its camera's own clock, seconds, shape ``(N,)``
            (e.g. presentation timestamps; gaps are dropped frames).
        max_offset_s: Largest relative offset searched between two cameras, seconds (None: any offset
            that leaves their streams overlapping).
        estimate_drift: Fit a clock-rate error per camera; None fits it when the longest stream spans
            over 30 s (shorter recordings cannot separate 100 ppm from noise: 3 ms over 30 s).
        cap_px: Ray misses at or above this many pixels (angle times focal length) count as
            disagreement in the pairwise search.
        f_scale_px: Scale of the soft-L1 loss of the joint refinement, pixels.
        kernel_frames: Width (standard deviation) of the temporal kernel that reads each stream, frames.
        refine: Run the joint refinement (else the fused pairwise offsets are returned, uncertainty NaN).
        piecewise: Recover a long recording piecewise, in time linear in its length (see the module
            docstring): the full offset search on each camera's first :data:`SEGMENT_S` seconds (or three
            times ``max_offset_s`` when that is longer), then offsets and drift from :data:`N_WINDOWS`
            windows spread over the whole recording. None: when the longest stream spans more than
            :data:`PIECEWISE_FROM_S`. Offsets must then be found in the first segment (cameras started
            within about half of it of each other).
        check_rates: Check the given rates against the images, or estimate them where none are given
            (:func:`gttnet.sync.rates.check_rates`): a rate the images contradict is replaced, with a
            warning naming the camera and the likely rate; without ``fps`` or frame times, a warning gives
            the estimated rates (relative to a reference camera; the absolute scale is assumed).

    Returns:
        :class:`~gttnet.sync.clocks.Clocks` for every camera of ``obs`` that sees the subject: a camera
        whose images carry no information (:func:`gttnet.sync.rates.blind_cameras`) gets no clock and is
        named in ``info["left_out"]`` ({camera id: reason}) with a warning. ``info`` also holds
        ``noise_px`` (the 2-D noise estimate, pixels) and ``rates`` (the rate check's findings).

    Raises:
        SequencingError: Without stream order or frame times.
        GttNetError: Fewer than two cameras that see the subject, or a camera with fewer than three images.
    """
    obs, frame_times_s, left_out = _leave_out_blind(obs, frame_times_s)
    rates = per_camera_rates(obs.cam_id, fps)
    tau = local_times(obs, rates, frame_times_s)
    timed = frame_times_s is not None or getattr(obs, "stream_time_s", None) is not None
    if fps is None and timed:
        # The cameras' own times are known: their nominal rates are the typical frame intervals.
        for c in rates:
            ts = np.sort(tau[obs.cam_id == c])
            if ts.size > 1 and np.median(np.diff(ts)) > 0:
                rates[c] = float(1.0 / np.median(np.diff(ts)))
    noise = _noise_px(obs, tau)
    rate_info = None
    if check_rates and np.unique(obs.cam_id).size >= 2:
        f0 = float(np.median(obs.K[:, 0, 0]))
        rates, tau, rate_info = rate_check(
            obs, tau, rates, given=fps is not None or timed, f_px=f0, cap=cap_px / f0, noise_px=noise,
            kernel_frames=kernel_frames,
        )  # fmt: skip
    cam = np.asarray(obs.cam_id)
    cams = np.unique(cam)
    if cams.size < 2:
        raise GttNetError(f"clock recovery needs at least two cameras, input has {cams.size}")
    f_px = float(np.median(obs.K[:, 0, 0]))
    opts: dict[str, Any] = {
        "f_px": f_px,
        "cap": cap_px / f_px,
        "max_offset_s": max_offset_s,
        "f_scale_px": f_scale_px,
        "refine": refine,
        "period": 1.0 / max(rates.values()),
        "n_joints": obs.n_joints,
    }
    first = np.array([tau[cam == c].min() for c in cams])
    span = max(float(tau[cam == c].max() - f) for c, f in zip(cams, first, strict=True))
    drift = bool(span > 30.0) if estimate_drift is None else bool(estimate_drift)
    if piecewise is None:
        piecewise = bool(span > PIECEWISE_FROM_S)
    if piecewise:
        o, d, std, info = _recover_piecewise(obs, tau, rates, kernel_frames, drift=drift, **opts)
    else:
        streams = camera_streams(obs, tau, rates, kernel_frames)
        o, d, std, info = _recover(streams, drift=drift, **opts)
    # Gauges: mean drift 0 (time rescaled), time 0 at the earliest first frame.
    m = 1e-6 * float(d.mean())
    o = o / (1.0 + m)
    d = ((1.0 + 1e-6 * d) / (1.0 + m) - 1.0) * 1e6
    start = o + (1.0 + 1e-6 * d) * first
    o = o - start.min()
    log.info("clocks: offsets %s s", np.array2string(o, precision=4))
    info.update({"noise_px": noise, "left_out": {str(c): why for c, why in left_out.items()}})
    if rate_info is not None:
        info["rates"] = rate_info
    for line in time_warnings({"cameras_left_out": left_out, "frame_rates": rate_info}):
        log.warning("%s", line)
    return Clocks(
        cameras=cams,
        offset_s=o,
        rate_hz=np.array([rates[int(c)] for c in cams]),
        drift_ppm=d,
        offset_std_s=std,
        info=info,
    )
