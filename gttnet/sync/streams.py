"""Camera streams of an order-free capture: candidate frame orders from several sources, kept by their clocks.

Without sequencing, each camera's frame order must be estimated before its clock can be recovered. Each
source gives a global rank of the images, and each camera's frames are put in the order of their ranks:

- ``pose-graph``: the spectral order of a pose graph over the pseudo-triangulated poses
  (:func:`gttnet.model.inputs.order_streams`); right where the motion does not come back to the same poses.
- ``pseudo``: the spectral order of the pseudo-triangulation's partner graph (each image linked to the
  other-camera images it triangulates best with: only images of nearly the same pose, so nearly the same
  moment, triangulate well); the cheapest source, and right where a fast motion at a low frame rate puts
  the pose graph and DLOE's order wrong.
- ``dloe``: the order DLOE recovers along with its reconstruction.
- ``gttnet``: the order GTT-Net recovers (only where a model runs anyway: as the fallback, or under ``auto``).
- ``root``: the position of the skeleton's centre along the main direction it travels (walking, running:
  a periodic motion whose poses repeat but whose position does not).

A wrong order leaves clocks that do not explain the images: the candidates' clocks are recovered, the
best-ordered streams (lowest noise estimate) first and the costly sources (a DLOE reconstruction) last, and
the first whose clock fit leaves what right clocks leave at the capture's noise is kept at once (the rest
are not tried: clock recovery is most of ``stream-sync``'s time); failing that, the candidate whose clock fit
leaves the lowest reprojection residual (among those whose clocks cover at least half as many ray pairs as
the best covered, and whose streams do not read as noisier than the others': a wrong order adds to the
frame-to-frame differences the noise is read from) is kept (:func:`choose_streams`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.geometry.noise import stream_noise_px
from gttnet.sync.clocks import Clocks
from gttnet.sync.recover import recover_clocks

__all__ = [
    "MISORDERED_NOISE",
    "ORDER_SOURCES",
    "StreamChoice",
    "choose_streams",
    "expected_clock_rms_px",
    "root_rank",
    "view_from_rank",
]

log = logging.getLogger(__name__)

#: Order sources ``stream-sync`` tries by default (``gttnet`` joins them where GTT-Net is the fallback).
ORDER_SOURCES = ("pose-graph", "pseudo", "dloe", "root")
#: A source whose streams' noise estimate exceeds the smallest by this factor is misordered: not kept
#: (unless every source is). 1.25 until the partner-graph source came: on the 2,400-image recording of
#: ``bench_scaling`` without sequencing its streams read 4 % noisier than the pose graph's yet fitted clocks
#: 8-15 % tighter, and keeping them cost 16.8 -> 18.3 mm; at 1.03 the quieter order wins such near-ties
#: (16.8 mm), and ``bench_auto --split val --n-seq 2 --seqs none`` picks and scores the same as at 1.25.
MISORDERED_NOISE = 1.03
#: Right clocks leave a clock-fit RMS of about ``sqrt((a sigma)^2 + b^2)`` pixels at 2-D noise sigma: the
#: noise seen through two smoothed rays, plus what interpolating between frames misses. Measured on the
#: paper recipe's test walks at sigma 1 / 2 / 5 px (30 Hz): 0.95 / 1.78 / 3.66 px.
_RMS_PER_NOISE = 0.72
_RMS_FLOOR_PX = 0.8


def expected_clock_rms_px(noise_px: float) -> float:
    """The clock-fit RMS right clocks leave at 2-D noise ``noise_px``, pixels.

    Example:
        >>> round(expected_clock_rms_px(2.0), 2)
        1.65
    """
    return float(np.hypot(_RMS_PER_NOISE * noise_px, _RMS_FLOOR_PX))


def view_from_rank(obs: Observations, rank: np.ndarray) -> Observations:
    """``obs`` marked ``partial``, each camera's frames in the order of the global ``rank`` (shape ``(N,)``)."""
    from gttnet.geometry.ordering import stream_ranks

    return replace(obs, sequencing="partial", stream_index=stream_ranks(np.asarray(rank), obs.cam_id))


def root_rank(x: np.ndarray) -> np.ndarray:
    """Rank of each image along the main direction the skeleton's centre travels, shape ``(N,)``.

    Args:
        x: Poses, shape ``(N, J, 3)``; NaN joints are ignored (an image without any: the median centre).

    Example:
        >>> x = np.zeros((4, 2, 3)); x[:, :, 0] = np.array([0.0, 2.0, 1.0, 3.0])[:, None]
        >>> root_rank(x).tolist()
        [0, 2, 1, 3]
    """
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x).all(axis=-1)
    cnt = ok.sum(axis=1)
    c = np.where(ok[..., None], x, 0.0).sum(axis=1) / np.maximum(cnt, 1)[:, None]
    good = cnt > 0
    if good.any():
        c[~good] = np.median(c[good], axis=0)
    d = c - c.mean(axis=0)
    axis = np.linalg.svd(d, full_matrices=False)[2][0]
    proj = d @ axis
    rank = np.empty(x.shape[0], dtype=np.int64)
    rank[np.argsort(proj, kind="stable")] = np.arange(x.shape[0])
    return rank


def _or_inf(x: float | None) -> float:
    return float("inf") if x is None else x


@dataclass(frozen=True)
class StreamChoice:
    """The camera streams kept and how every source fared.

    Args:
        source: Name of the kept source, or None when no source's clocks could be recovered.
        view: The kept ``partial`` view (None with ``source``).
        clocks: Its recovered clocks (None with ``source``).
        noise_px: The capture's 2-D noise estimate, pixels: the smallest over the sources' streams (a wrong
            order only adds to the second differences it is read from), or None.
        table: Per source: ``rms_px`` (clock fit residual), ``noise_px``, ``n_residuals`` and ``seconds`` (its
            clock recovery), or ``error``, or ``same_as`` (a source with the same streams), or ``skipped``
            (with the reason).
    """

    source: str | None
    view: Observations | None
    clocks: Clocks | None
    noise_px: float | None
    table: dict = field(default_factory=dict)


def _streams(v: Observations) -> np.ndarray:
    """Each image's frame index within its camera (``partial`` views carry it)."""
    assert v.stream_index is not None
    return np.asarray(v.stream_index)


def _smallest(noise: Mapping[str, float | None]) -> float | None:
    """The capture's noise estimate: the smallest over the streams measured (a wrong order only adds)."""
    measured = [s for s in noise.values() if s is not None]
    return min(measured) if measured else None


def _within(rms: float | None, noise: Mapping[str, float | None], name: str, limit: float | None) -> bool:
    """Whether clocks leaving ``rms`` px are within ``limit`` x the expected RMS, ``name``'s streams quiet."""
    sigma = _smallest(noise)
    if limit is None or sigma is None or rms is None:
        return False
    return rms <= limit * expected_clock_rms_px(sigma) and _or_inf(noise[name]) <= MISORDERED_NOISE * sigma


def _lowest_fair(names: list[str], table: dict[str, dict], noise: Mapping[str, float | None], sigma) -> str:
    """The lowest clock residual among ``names`` covering half the most ray pairs, streams not misordered."""
    most = max(table[n]["n_residuals"] for n in names)
    fair = [
        n
        for n in names
        if table[n]["n_residuals"] >= 0.5 * most
        and table[n]["rms_px"] is not None
        and _or_inf(noise[n]) <= MISORDERED_NOISE * _or_inf(sigma)
    ]
    return min(fair or names, key=lambda n: table[n]["rms_px"] or np.inf)


def choose_streams(
    views: Mapping[str, Observations],
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None,
    lazy: Mapping[str, Callable[[], Observations | None]] | None = None,
    accept_rms_noise: float | None = None,
    lazy_rms_noise: float | None = None,
) -> StreamChoice:
    """Recover the candidate views' clocks, cheapest first, and keep the one that explains the images best.

    The views are tried in the order of their noise estimates (the best-ordered streams first), then the
    ``lazy`` sources in their given order (each made only when reached: e.g. DLOE's order, a whole
    reconstruction). A view whose streams are those of a view already tried is not tried again (``same_as``).
    The frame rates are checked (or, without ``fps``, estimated) on the first view tried, then held for the
    others. Clock fits are judged by their RMS over what right clocks leave at the capture's noise estimate
    so far (:func:`expected_clock_rms_px`), among views whose own noise estimate is within
    :data:`MISORDERED_NOISE` times the smallest: a view at most ``accept_rms_noise`` is kept at once (the
    sources after it are marked ``skipped``), and the lazy sources are made only when no view so far is at
    most ``lazy_rms_noise``. Otherwise, among the views whose clock fit covers at least half as many ray
    pairs as the best covered one and whose noise estimate is within :data:`MISORDERED_NOISE` times the
    smallest, the lowest clock residual wins.

    Args:
        views: Candidate ``partial`` views of one capture, by source name.
        fps: Nominal frame rates, as :func:`gttnet.sync.recover_clocks` takes them.
        lazy: Further sources by name, each a function making its ``partial`` view (None: no view).
        accept_rms_noise: The ratio at which a view is kept at once; None tries every source.
        lazy_rms_noise: The ratio at which no lazy source is made; None makes them whenever reached.

    Returns:
        The :class:`StreamChoice`.
    """
    table: dict[str, dict] = {}
    noise: dict[str, float | None] = {}
    made: dict[str, Observations] = {}
    clocks: dict[str, Clocks] = {}

    def measure(name: str, v: Observations) -> None:
        assert v.stream_index is not None  # partial views
        made[name] = v
        noise[name] = stream_noise_px(v.keypoints_px, v.visible, v.cam_id, v.stream_index)
        table[name] = {"noise_px": noise[name]}

    def within(name: str, limit: float | None) -> bool:
        return _within(table[name].get("rms_px"), noise, name, limit)

    for name, v in views.items():
        measure(name, v)
    pending: list[tuple[str, Callable[[], Observations | None] | None]] = [
        (n, None) for n in sorted(views, key=lambda n: _or_inf(noise[n]))
    ]
    pending += [(n, make) for n, make in (lazy or {}).items() if n not in views]
    rates: float | Sequence[float] | Mapping[int, float] | None = fps
    rate_info = None
    accepted = None
    tried: list[str] = []
    for i, (name, make) in enumerate(pending):
        if make is not None:
            good = [n for n in clocks if within(n, lazy_rms_noise)]
            lazy_view = None if good else make()
            if lazy_view is None:
                why = f"{good[0]}'s clocks are within {lazy_rms_noise}x the expected" if good else ""
                table[name] = {"skipped": why} if good else {"error": "no order"}
                continue
            measure(name, lazy_view)
        same = [n for n in tried if np.array_equal(_streams(made[n]), _streams(made[name]))]
        tried.append(name)
        if same:
            table[name]["same_as"] = same[0]
            continue
        first = rate_info is None
        t0 = time.perf_counter()
        try:
            cl = recover_clocks(made[name], fps=rates, check_rates=first)
        except GttNetError as exc:
            table[name]["error"] = str(exc)
            continue
        finally:
            table[name]["seconds"] = round(time.perf_counter() - t0, 3)
        if first:
            rate_info = cl.info.get("rates")
            rates = {int(c): float(r) for c, r in zip(cl.cameras, cl.rate_hz, strict=True)}
        clocks[name] = cl
        table[name].update({"rms_px": cl.info.get("rms_px"), "n_residuals": cl.info.get("n_residuals", 0)})
        if within(name, accept_rms_noise):
            accepted = name
            for rest, _ in pending[i + 1 :]:
                table[rest] = {**table.get(rest, {}), "skipped": f"{name}'s clocks explain the images"}
            break
    sigma = _smallest(noise)
    if not clocks:
        return StreamChoice(None, None, None, sigma, table)
    best = accepted if accepted is not None else _lowest_fair(list(clocks), table, noise, sigma)
    cl = clocks[best]
    if rate_info is not None:  # the rates were checked on another view: report that check
        cl = replace(cl, info={**cl.info, "rates": rate_info})
    log.info("stream-sync: order sources %s; kept %s", table, best)
    return StreamChoice(best, made[best], cl, sigma, table)
