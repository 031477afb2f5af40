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
of images N for a fixed search range, never an N x N matrix.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.sync.clocks import Clocks, local_times, per_camera_rates

__all__ = ["Stream", "ray_meeting_error", "pair_offset", "recover_clocks"]

log = logging.getLogger(__name__)

_SIN2_MIN = 1e-3  # rays closer than ~1.8 degrees to parallel say nothing about time


@dataclass(frozen=True)
class Stream:
    """One camera's images in its own time order, smoothed by a Gaussian kernel in time.

    Each frame's rays are replaced by a kernel-weighted mean of the nearby frames (width ``kernel_s``);
    between frames they are linearly interpolated. Smoothing makes the noise of neighbouring samples
    correlated, so an interpolated ray averages about as much noise at every fractional position (and
    the remaining difference is divided out, see :meth:`at`): no sub-frame shift is favoured by the noise
    alone. Both streams of a pair are smoothed alike, so the motion is blurred alike. Arrays are stored
    component-major for speed.

    Args:
        camera: Camera id.
        images: Index of each frame in the input observations, shape ``(n,)``.
        tau: Local time of each frame, seconds, shape ``(n,)`` increasing.
        rays: Smoothed unit viewing rays in world, shape ``(3, n, J)``.
        centers: Smoothed camera centres in world, metres, shape ``(3, n)``.
        ok: Whether a frame's smoothed joint has enough observed support, shape ``(n, J)``.
        var: Noise variance of each frame's smoothed ray relative to one raw frame, shape ``(n,)``.
        cov: Noise covariance of consecutive smoothed frames relative to one raw frame, shape ``(n,)``
            (entry k: frames k and k + 1).
        max_gap_s: Longest interval between consecutive frames that is interpolated across.
    """

    camera: int
    images: np.ndarray
    tau: np.ndarray
    rays: np.ndarray
    centers: np.ndarray
    ok: np.ndarray
    var: np.ndarray
    cov: np.ndarray
    max_gap_s: float

    @classmethod
    def build(
        cls,
        camera: int,
        images: np.ndarray,
        tau: np.ndarray,
        rays: np.ndarray,
        centers: np.ndarray,
        visible: np.ndarray,
        *,
        kernel_s: float,
        max_gap_s: float,
    ) -> Stream:
        """Smooth raw rays ``(n, J, 3)``, centres ``(n, 3)`` and visibility ``(n, J)`` of one stream."""
        n = tau.shape[0]
        half = max(1, int(np.ceil(2.5 * kernel_s / max(float(np.median(np.diff(tau))), 1e-9))))
        idx = np.arange(n)[:, None] + np.arange(-half, half + 1)[None, :]
        inside = (idx >= 0) & (idx < n)
        idx = np.clip(idx, 0, n - 1)
        dt = (tau[:, None] - tau[idx]) / kernel_s
        g = np.exp(-0.5 * dt * dt) * inside  # (n, W)
        gs = g.sum(axis=1)
        gv = g[:, :, None] * visible[idx]  # (n, W, J)
        wv = gv.sum(axis=1)
        r = np.einsum("nwj,nwja->anj", gv, rays[idx])
        r /= np.maximum(np.sqrt((r * r).sum(axis=0)), 1e-12)
        c = np.einsum("nw,nwa->an", g, centers[idx]) / gs
        gn = g / gs[:, None]
        var = (gn * gn).sum(axis=1)
        # Covariance of smoothed frames k and k + 1: raw frame k - half + j is tap j of row k and tap j - 1 of
        # row k + 1 (taps outside the stream have zero weight).
        cov = np.zeros(n)
        cov[:-1] = (gn[:-1, 1:] * gn[1:, :-1]).sum(axis=1)
        ok = wv >= 0.5 * gs[:, None]
        return cls(camera, images, tau, np.ascontiguousarray(r), c, ok, var, cov, max_gap_s)

    def at(self, tq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Smoothed rays linearly interpolated at local times ``tq`` (shape ``(m,)``).

        Returns:
            ``(rays (3, m, J), centers (3, m), ok (m, J), var (m,))``: ``ok`` is False outside the
            stream, across a gap longer than ``max_gap_s`` and where a bracketing frame lacks support;
            ``var`` is the noise variance of the interpolated ray relative to one raw frame.
        """
        n = self.tau.shape[0]
        k = np.clip(np.searchsorted(self.tau, tq, side="right") - 1, 0, n - 2)
        t0, t1 = self.tau[k], self.tau[k + 1]
        w = (tq - t0) / (t1 - t0)
        inside = (w >= 0.0) & (w <= 1.0) & (t1 - t0 <= self.max_gap_s)
        w = np.clip(w, 0.0, 1.0)
        u = 1.0 - w
        r = u[None, :, None] * self.rays[:, k] + w[None, :, None] * self.rays[:, k + 1]
        r /= np.maximum(np.sqrt((r * r).sum(axis=0)), 1e-12)
        c = u[None] * self.centers[:, k] + w[None] * self.centers[:, k + 1]
        var = u * u * self.var[k] + w * w * self.var[k + 1] + 2.0 * u * w * self.cov[k]
        return r, c, inside[:, None] & self.ok[k] & self.ok[k + 1], var


def ray_meeting_error(
    c1: np.ndarray, r1: np.ndarray, c2: np.ndarray, r2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Angular miss of two rays: closest-point distance over mean depth, radians.

    Args:
        c1: Ray origins, shape ``(3, ...)`` (component first).
        r1: Unit directions, shape ``(3, ...)``.
        c2: Ray origins, shape ``(3, ...)``.
        r2: Unit directions, shape ``(3, ...)``.

    Returns:
        ``(error, ok)``, shape ``(...)``: ``ok`` is False for near-parallel rays or a meeting point behind
        either camera.

    Example:
        >>> e, ok = ray_meeting_error(np.zeros(3), np.array([1.0, 0, 0]), np.array([2.0, -2, 0.2]),
        ...                           np.array([0, 1.0, 0]))
        >>> round(float(e), 3), bool(ok)
        (0.1, True)
    """
    b = r1[0] * r2[0] + r1[1] * r2[1] + r1[2] * r2[2]
    w0 = [c1[i] - c2[i] for i in range(3)]
    d = r1[0] * w0[0] + r1[1] * w0[1] + r1[2] * w0[2]
    e = r2[0] * w0[0] + r2[1] * w0[1] + r2[2] * w0[2]
    sin2 = 1.0 - b * b
    ok = sin2 > _SIN2_MIN
    inv = 1.0 / np.maximum(sin2, _SIN2_MIN)
    s = (b * e - d) * inv
    t = (e - b * d) * inv
    g2 = sum((w0[i] + s * r1[i] - t * r2[i]) ** 2 for i in range(3))
    ok &= (s > 0) & (t > 0)
    return np.where(ok, np.sqrt(g2) / np.maximum(0.5 * (s + t), 1e-9), 0.0), ok


def _streams(
    obs: Observations, tau: np.ndarray, rates: Mapping[int, float], kernel_frames: float
) -> list[Stream]:
    rays, centers = obs.rays(), obs.centers()
    out = []
    for c in np.unique(obs.cam_id):
        sel = np.flatnonzero(obs.cam_id == c)
        sel = sel[np.argsort(tau[sel], kind="stable")]
        if sel.size < 3:
            raise GttNetError(f"clock recovery: camera {int(c)} has {sel.size} image(s), needs at least 3")
        out.append(
            Stream.build(
                int(c),
                sel,
                tau[sel],
                rays[sel],
                centers[sel],
                obs.visible[sel],
                kernel_s=kernel_frames / rates[int(c)],
                max_gap_s=2.5 / rates[int(c)],
            )
        )
    return out


def _pair_errors(a: Stream, b: Stream, ia: np.ndarray, tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noise-normalised ray-meeting errors of a camera pair at one shift, shape ``(m, J)``.

    Ray-meeting errors of ``a``'s smoothed frames ``ia`` against ``b`` interpolated at ``tq``, shape
    ``(m, J)``; each divided by the square root of the pair's relative noise variance, so pure noise
    scores alike at every shift.
    """
    rb, cb, okb, vb = b.at(tq)
    err, ok = ray_meeting_error(a.centers[:, ia, None], a.rays[:, ia], cb[:, :, None], rb)
    ok &= okb & a.ok[ia]
    err = err / np.sqrt(a.var[ia] + vb)[:, None]
    return np.where(ok, err, 0.0), ok


def _consensus(a: Stream, b: Stream, ia: np.ndarray, shifts: np.ndarray, cap: float) -> np.ndarray:
    """Consensus score of each candidate shift.

    Consensus score of each shift (``tau_b = tau_a + shift``): sum of ``(1 - (e / cap)^2)^2`` over
    meeting rays with ``e < cap``. Rewards overlap only where the rays agree.
    """
    score = np.empty(shifts.shape[0])
    chunk = max(1, 200_000 // max(ia.size * a.rays.shape[2], 1))
    for s0 in range(0, shifts.shape[0], chunk):
        sh = shifts[s0 : s0 + chunk]
        tq = (a.tau[ia][None, :] + sh[:, None]).ravel()
        rep = np.tile(ia, sh.shape[0])
        err, ok = _pair_errors(a, b, rep, tq)
        u = np.where(ok, np.clip(1.0 - (err / cap) ** 2, 0.0, None), 0.0) ** 2
        score[s0 : s0 + chunk] = u.reshape(sh.shape[0], -1).sum(axis=1)
    return score


def pair_offset(
    a: Stream,
    b: Stream,
    *,
    cap: float,
    max_offset_s: float | None = None,
    max_coarse_images: int = 48,
) -> tuple[float, float, float]:
    """Shift ``delta`` with ``tau_b = tau_a + delta`` at the same instant, from the ray-meeting consensus.

    A coarse grid (step: two frames of the faster camera) over every shift that leaves the streams
    overlapping (or ``|delta| <= max_offset_s``), on at most ``max_coarse_images`` frames of ``a``; a fine
    grid (1/8 of the coarse step) around the best coarse shift on all frames; a parabola through the best
    fine shift and its neighbours.

    Args:
        a: First stream.
        b: Second stream.
        cap: Errors at or above this (radians) count as disagreement.
        max_offset_s: Largest ``|delta|`` searched, seconds (None: any overlapping shift).
        max_coarse_images: Frames of ``a`` used by the coarse grid.

    Returns:
        ``(delta_s, score, peak_ratio)``: the shift, its consensus score and the ratio of the best score
        away from the peak (beyond two coarse steps) to the peak (near 1: ambiguous).
    """
    fa = 1.0 / np.median(np.diff(a.tau))
    fb = 1.0 / np.median(np.diff(b.tau))
    h = 2.0 / max(fa, fb)
    lo, hi = b.tau[0] - a.tau[-1], b.tau[-1] - a.tau[0]
    if max_offset_s is not None:
        lo, hi = max(lo, -max_offset_s), min(hi, max_offset_s)
    if hi <= lo:
        raise GttNetError(
            f"clock recovery: cameras {a.camera} and {b.camera} cannot overlap within max_offset_s={max_offset_s}"
        )
    coarse = np.arange(lo, hi + h, h)
    ia = np.unique(
        np.linspace(0, a.tau.shape[0] - 1, min(max_coarse_images, a.tau.shape[0])).round().astype(int)
    )
    sc = _consensus(a, b, ia, coarse, cap)
    best = int(np.argmax(sc))
    far = np.abs(coarse - coarse[best]) > 2.0 * h
    ratio = float(sc[far].max() / sc[best]) if far.any() and sc[best] > 0 else 0.0
    fine = coarse[best] + np.linspace(-1.5 * h, 1.5 * h, 25)
    all_a = np.arange(a.tau.shape[0])
    sf = _consensus(a, b, all_a, fine, cap)
    k = int(np.clip(np.argmax(sf), 1, fine.shape[0] - 2))
    y0, y1, y2 = sf[k - 1], sf[k], sf[k + 1]
    den = y0 - 2.0 * y1 + y2
    step = fine[1] - fine[0]
    frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    return float(fine[k] + np.clip(frac, -1.0, 1.0) * step), float(sf[k]), ratio


def _fuse_offsets(n: int, pairs: list[tuple[int, int, float, float]], scale: float) -> np.ndarray:
    """Camera offsets from pairwise offset equations by Huber IRLS.

    Offsets ``o`` (``o[0] = 0``) from pair equations ``o_a - o_b = delta_ab`` by IRLS with a Huber
    weight of width ``scale`` seconds; each equation weighted by its consensus score.
    """
    A = np.zeros((len(pairs), n))
    y = np.zeros(len(pairs))
    w0 = np.zeros(len(pairs))
    for r, (i, j, delta, score) in enumerate(pairs):
        A[r, i], A[r, j], y[r], w0[r] = 1.0, -1.0, delta, max(score, 1e-9)
    w = w0.copy()
    o = np.zeros(n)
    for _ in range(20):
        sw = np.sqrt(w)
        sol, *_ = np.linalg.lstsq(A[:, 1:] * sw[:, None], y * sw, rcond=None)
        o = np.concatenate([[0.0], sol])
        res = np.abs(A @ o - y)
        w = w0 * np.where(res <= scale, 1.0, scale / np.maximum(res, 1e-12))
    return o


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
            err, ok = _pair_errors(a, b, np.arange(a.tau.shape[0]), tq)
            out.append((err * self.f).ravel())
            nv += int(ok.sum())
            pos += size
        if only is None:
            self.n_valid = nv
        return np.concatenate(out)


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

    Returns:
        :class:`~gttnet.sync.clocks.Clocks` for every camera in ``obs``.

    Raises:
        SequencingError: Without stream order or frame times.
        GttNetError: Fewer than two cameras, or a camera with fewer than two images.
    """
    rates = per_camera_rates(obs.cam_id, fps)
    tau = local_times(obs, rates, frame_times_s)
    if fps is None and (frame_times_s is not None or getattr(obs, "stream_time_s", None) is not None):
        # The cameras' own times are known: their nominal rates are the typical frame intervals.
        for c in rates:
            ts = np.sort(tau[obs.cam_id == c])
            if ts.size > 1 and np.median(np.diff(ts)) > 0:
                rates[c] = float(1.0 / np.median(np.diff(ts)))
    streams = _streams(obs, tau, rates, kernel_frames)
    v = len(streams)
    if v < 2:
        raise GttNetError(f"clock recovery needs at least two cameras, input has {v}")
    f_px = float(np.median(obs.K[:, 0, 0]))
    cap = cap_px / f_px
    # Pairwise search, then fusion over the camera graph.
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
    period = 1.0 / max(rates.values())
    o = _fuse_offsets(v, pairs, scale=period)
    span = max(float(s.tau[-1] - s.tau[0]) for s in streams)
    drift = span > 30.0 if estimate_drift is None else bool(estimate_drift)
    d = np.zeros(v)
    std = np.full(v, np.nan)
    info: dict = {"front_end": "epipolar", "pairs": pair_info, "estimate_drift": drift, "refined": refine}
    if refine:
        ref = _Refiner(streams, f_px, drift)
        p0 = np.concatenate([o[1:], np.zeros(v - 1)]) if drift else o[1:].copy()
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
        res = least_squares(
            fun, p0, jac=jac, loss="soft_l1", f_scale=f_scale_px, x_scale=x_scale, max_nfev=50
        )
        o, d = ref.unpack(res.x)
        ref.residuals(res.x)
        dof = max(ref.n_valid - res.x.size, 1)
        J = res.jac
        try:
            cov = np.linalg.inv(J.T @ J) * (2.0 * res.cost / dof)
        except np.linalg.LinAlgError:
            cov = np.full((res.x.size, res.x.size), np.nan)
        # Joints of one image share its timing error: count images, not joints, as independent samples.
        cov *= obs.n_joints
        full = np.zeros((v, v))
        full[1:, 1:] = cov[: v - 1, : v - 1]
        centre = np.eye(v) - 1.0 / v
        std = np.sqrt(np.clip(np.diag(centre @ full @ centre.T), 0.0, None))
        info.update(
            {
                "nfev": int(res.nfev),
                "rms_px": float(np.sqrt(2.0 * res.cost / dof)),
                "n_residuals": ref.n_valid,
            }
        )
    # Gauges: mean drift 0 (time rescaled), time 0 at the earliest first frame.
    m = 1e-6 * float(d.mean())
    o = o / (1.0 + m)
    d = ((1.0 + 1e-6 * d) / (1.0 + m) - 1.0) * 1e6
    first = np.array([o[k] + (1.0 + 1e-6 * d[k]) * streams[k].tau[0] for k in range(v)])
    o = o - first.min()
    cams = np.array([s.camera for s in streams])
    log.info("clocks: offsets %s s", np.array2string(o, precision=4))
    return Clocks(
        cameras=cams,
        offset_s=o,
        rate_hz=np.array([rates[int(c)] for c in cams]),
        drift_ppm=d,
        offset_std_s=std,
        info=info,
    )
