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
- ``gttnet``: the order GTT-Net recovers (only where a model runs anyway, e.g. as the fallback).
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
#: (unless every source is).
MISORDERED_NOISE = 1.25
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
        table: Per source: ``rms_px`` (clock fit residual), ``noise_px``, ``n_residuals`` or ``error``.
    """

    source: str | None
    view: Observations | None
    clocks: Clocks | None
    noise_px: float | None
    table: dict = field(default_factory=dict)


def choose_streams(
    views: Mapping[str, Observations],
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None,
    lazy: Mapping[str, Callable[[], Observations | None]] | None = None,
    accept_rms_noise: float | None = None,
) -> StreamChoice:
    """Recover the clocks of the candidate views, cheapest evidence first, and keep the one that explains the images best.

    The views are tried in the order of their noise estimates (the best-ordered streams first), then the
    ``lazy`` sources in their given order (each made only when reached: e.g. DLOE's order, a whole
    reconstruction). The frame rates are checked (or, without ``fps``, estimated) on the first view tried,
    then held for the others. With ``accept_rms_noise``, a view whose clock fit leaves at most that multiple
    of what right clocks leave at the capture's noise estimate so far (:func:`expected_clock_rms_px`) and
    whose own noise estimate is within
    :data:`MISORDERED_NOISE` times the smallest is kept at once: the sources after it are not tried
    (``table`` marks them ``skipped``). Otherwise, among the views whose clock fit covers at least half as
    many ray pairs as the best covered one and whose noise estimate is within :data:`MISORDERED_NOISE`
    times the smallest, the lowest clock residual wins.

    Args:
        views: Candidate ``partial`` views of one capture, by source name.
        fps: Nominal frame rates, as :func:`gttnet.sync.recover_clocks` takes them.
        lazy: Further sources by name, each a function making its ``partial`` view (None: no view).
        accept_rms_noise: The multiple of :func:`expected_clock_rms_px` at which a view is kept at once; None
            tries every source.

    Returns:
        The :class:`StreamChoice`.
    """
    table: dict[str, dict] = {}
    noise: dict[str, float | None] = {}
    made: dict[str, Observations] = {}

    def measure(name: str, v: Observations) -> None:
        assert v.stream_index is not None  # partial views
        made[name] = v
        noise[name] = stream_noise_px(v.keypoints_px, v.visible, v.cam_id, v.stream_index)
        table[name] = {"noise_px": noise[name]}

    def sigma_now() -> float | None:
        measured = [s for s in noise.values() if s is not None]
        return min(measured) if measured else None

    for name, v in views.items():
        measure(name, v)
    pending: list[tuple[str, Callable[[], Observations | None] | None]] = [
        (n, None) for n in sorted(views, key=lambda n: _or_inf(noise[n]))
    ]
    pending += [(n, make) for n, make in (lazy or {}).items() if n not in views]
    clocks: dict[str, Clocks] = {}
    rates: float | Sequence[float] | Mapping[int, float] | None = fps
    rate_info = None
    accepted = None
    for i, (name, make) in enumerate(pending):
        if make is not None:
            lazy_view = make()
            if lazy_view is None:
                table[name] = {"error": "no order"}
                continue
            measure(name, lazy_view)
        first = rate_info is None
        try:
            cl = recover_clocks(made[name], fps=rates, check_rates=first)
        except GttNetError as exc:
            table[name]["error"] = str(exc)
            continue
        if first:
            rate_info = cl.info.get("rates")
            rates = {int(c): float(r) for c, r in zip(cl.cameras, cl.rate_hz, strict=True)}
        clocks[name] = cl
        table[name].update({"rms_px": cl.info.get("rms_px"), "n_residuals": cl.info.get("n_residuals", 0)})
        sigma = sigma_now()
        rms = cl.info.get("rms_px")
        if (
            accept_rms_noise is not None
            and sigma is not None
            and rms is not None
            and rms <= accept_rms_noise * expected_clock_rms_px(sigma)
            and _or_inf(noise[name]) <= MISORDERED_NOISE * sigma
        ):
            accepted = name
            for rest, _ in pending[i + 1 :]:
                table[rest] = {**table.get(rest, {}), "skipped": f"{name}'s clocks explain the images"}
            break
    sigma = sigma_now()
    if not clocks:
        return StreamChoice(None, None, None, sigma, table)
    if accepted is not None:
        best = accepted
    else:
        most = max(table[n]["n_residuals"] for n in clocks)
        fair = [
            n
            for n in clocks
            if table[n]["n_residuals"] >= 0.5 * most
            and table[n]["rms_px"] is not None
            and _or_inf(noise[n]) <= MISORDERED_NOISE * _or_inf(sigma)
        ]
        best = min(fair or list(clocks), key=lambda n: table[n]["rms_px"] or np.inf)
    cl = clocks[best]
    if rate_info is not None:  # the rates were checked on another view: report that check
        cl = replace(cl, info={**cl.info, "rates": rate_info})
    log.info("stream-sync: order sources %s; kept %s", table, best)
    return StreamChoice(best, made[best], cl, sigma, table)
