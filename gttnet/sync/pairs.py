"""Pairwise clock offsets: how far one camera stream must be shifted in time for its rays to meet another's.

Two calibrated cameras that film the same instant see rays that meet at every joint; a stream shifted in
time sees rays that miss. :func:`pair_offset` finds, for one pair of cameras, the shift that makes one
stream's rays (interpolated at the same instant) meet the other's, by a coarse-to-fine search scored by a
robust consensus over the images. Fusing the pairs into one clock per camera is :mod:`gttnet.sync.fusion`;
the whole recovery is :func:`gttnet.sync.recover.recover_clocks`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError

__all__ = ["Stream", "camera_streams", "pair_errors", "pair_offset", "ray_meeting_error"]

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


def camera_streams(
    obs: Observations,
    tau: np.ndarray,
    rates: Mapping[int, float],
    kernel_frames: float,
    idx: np.ndarray | None = None,
) -> list[Stream]:
    """One :class:`Stream` per camera (ascending id) of the images ``idx`` (default: all)."""
    if idx is not None:
        idx = np.asarray(idx, dtype=np.int64)
        sub = camera_streams(obs.take(idx), tau[idx], rates, kernel_frames)
        return [replace(st, images=idx[st.images]) for st in sub]
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


def pair_errors(a: Stream, b: Stream, ia: np.ndarray, tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
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
        err, ok = pair_errors(a, b, rep, tq)
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
    around_s: float = 0.0,
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
        max_offset_s: Largest ``|delta - around_s|`` searched, seconds (None: any overlapping shift).
        max_coarse_images: Frames of ``a`` used by the coarse grid.
        around_s: Centre of the searched range, seconds (a prediction of ``delta``).

    Returns:
        ``(delta_s, score, peak_ratio)``: the shift, its consensus score and the ratio of the best score
        away from the peak (beyond two coarse steps) to the peak (near 1: ambiguous).
    """
    fa = 1.0 / np.median(np.diff(a.tau))
    fb = 1.0 / np.median(np.diff(b.tau))
    h = 2.0 / max(fa, fb)
    lo, hi = b.tau[0] - a.tau[-1], b.tau[-1] - a.tau[0]
    if max_offset_s is not None:
        lo, hi = max(lo, around_s - max_offset_s), min(hi, around_s + max_offset_s)
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
