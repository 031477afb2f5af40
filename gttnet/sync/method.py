"""The ``sync`` reconstruction method: recover the cameras' clocks, then solve with the timestamps."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, MutableMapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.methods import Reconstruction, register_method
from gttnet.sync.clocks import Clocks, apply_clocks, clock_times
from gttnet.sync.rates import time_warnings
from gttnet.sync.recover import recover_clocks
from gttnet.sync.streams import (
    ORDER_SOURCES,
    choose_streams,
    expected_clock_rms_px,
    root_rank,
    view_from_rank,
)

__all__ = [
    "AUTO",
    "SOLVERS",
    "STREAM_SYNC_ACCEPT_RMS_NOISE",
    "STREAM_SYNC_MAX_RMS_NOISE",
    "STREAM_SYNC_MAX_RMS_PX",
    "count_rates",
    "order_free_fallback",
    "reconstruct_stream_sync",
    "reconstruct_sync",
    "time_checks",
]

log = logging.getLogger(__name__)

#: Full-sequencing solvers ``sync`` can hand the recovered timestamps to, with their options.
#: HPF's prior weight is cross-validated over 3 folds and a coarse-to-fine bracket of weights (27 solves
#: instead of 65): the same mean MPJPE on the paper protocol's validation split, a third of the time.
SOLVERS: dict[str, dict] = {"hpf": {"spacing": "time", "n_folds": 3, "search": "bracket"}, "dct": {}}


@register_method(
    "sync",
    requires="partial",
    needs="each camera's frame order",
    summary="recover the cameras' clocks from the skeletons, then the high-pass-filter prior on them",
)
def reconstruct_sync(
    obs: Observations,
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None = None,
    frame_times_s: np.ndarray | None = None,
    max_offset_s: float | None = None,
    estimate_drift: bool | None = None,
    solver: str = "hpf",
    clocks: Clocks | None = None,
    solver_options: Mapping[str, Any] | None = None,
) -> Reconstruction:
    """Clock recovery (:func:`gttnet.sync.recover_clocks`) then a full-sequencing solver on the recovered times.

    Args:
        obs: Observations with each camera's frame order (``partial``; a ``full`` input's timestamps are
            ignored and re-estimated).
        fps: Nominal frame rate per camera (one value, a list by camera id, or ``{camera: Hz}``), checked
            against the images (:func:`gttnet.sync.rates.check_rates`); None: estimated, with a warning.
        frame_times_s: Per-image times on each camera's own clock, seconds, shape ``(N,)``.
        max_offset_s: Largest offset searched between two cameras, seconds.
        estimate_drift: Fit per-camera clock drift (None: when a stream spans over 30 s).
        solver: ``"hpf"`` (default: the most accurate full-sequencing solver of the project's evaluation)
            or ``"dct"``.
        clocks: Clocks already recovered for these cameras (e.g. over the whole recording a window of it
            comes from, :func:`gttnet.windowed.reconstruct_windowed`): used as they are, nothing is
            recovered (``fps``, ``max_offset_s`` and ``estimate_drift`` are then unused).
        solver_options: Options of the solver over :data:`SOLVERS`' (e.g. HPF's ``lam_start``).

    Returns:
        Reconstruction in the input's image order; ``order`` ranks the recovered times (images of cameras
        left out last); ``info`` holds ``clock_offsets_s`` ({camera: s}), ``clocks`` (the full table),
        ``timestamp_s`` (per image, input order; None for a camera left out), the time spent in each stage,
        and :func:`time_checks`'s keys: ``clock_residual_px``, ``noise_px``, ``frame_rates``,
        ``cameras_left_out`` and ``time_warnings``. A camera whose images carry no information for its
        clock (:func:`gttnet.sync.rates.blind_cameras`) gets no clock: its images' poses are NaN.
    """
    if solver not in SOLVERS:
        raise ValueError(f"sync: solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    t0 = time.perf_counter()
    if clocks is None:
        clocks = recover_clocks(
            obs,
            fps=fps,
            frame_times_s=frame_times_s,
            max_offset_s=max_offset_s,
            estimate_drift=estimate_drift,
        )
    t1 = time.perf_counter()
    rec = _timed_solve(obs, clocks, frame_times_s=frame_times_s, solver=solver, options=solver_options)
    return replace(rec, info={**rec.info, "sync_seconds": t1 - t0})


def _timed_solve(
    obs: Observations,
    clocks: Clocks,
    *,
    frame_times_s: np.ndarray | None,
    solver: str,
    options: Mapping[str, Any] | None = None,
) -> Reconstruction:
    """The full-sequencing ``solver`` on the times ``clocks`` give; images of cameras without a clock NaN.

    The solver's function is called directly: its result is an intermediate (the caller's reconstruction is
    assessed as a whole), so neither its self-assessment nor an order from its affinity is computed.
    """
    from gttnet.methods import method_spec

    left = {int(c): why for c, why in clocks.info.get("left_out", {}).items()}
    timed = np.flatnonzero(~np.isin(obs.cam_id, list(left)))  # images of cameras with a clock
    sub = obs.take(timed) if left else obs
    ft = None if frame_times_s is None else np.asarray(frame_times_s)[timed]
    t_sub = clock_times(sub, clocks, frame_times_s=ft)
    t0 = time.perf_counter()
    opts = {**SOLVERS[solver], **(options or {})}
    inner = method_spec(solver).fn(apply_clocks(sub, clocks, frame_times_s=ft), **opts)
    solve_seconds = time.perf_counter() - t0
    seq = timed[np.argsort(t_sub, kind="stable")]
    X = np.full((obs.n_images, obs.n_joints, 3), np.nan)  # images without a clock: no pose
    X[seq] = inner.points3d
    X[:, ~np.asarray(sub.visible, dtype=bool).any(axis=0)] = np.nan  # joints no timed image observes
    rest = np.setdiff1d(np.arange(obs.n_images), timed)
    rank = np.empty(obs.n_images, dtype=np.int64)
    rank[np.r_[seq, rest[np.lexsort((_frame_order(obs)[rest], obs.cam_id[rest]))]]] = np.arange(obs.n_images)
    t = np.full(obs.n_images, np.nan)
    t[timed] = t_sub
    info = {
        "clock_offsets_s": {
            str(int(c)): float(o) for c, o in zip(clocks.cameras, clocks.offset_s, strict=True)
        },
        "clocks": clocks.to_dict(),
        "timestamp_s": [None if not np.isfinite(x) else float(x) for x in t],
        "solver": solver,
        "solver_info": inner.info,
        "solve_seconds": solve_seconds,
        **time_checks(clocks),
    }
    return Reconstruction(points3d=X, order=rank, info=info)


def _frame_order(obs: Observations) -> np.ndarray:
    """Each image's frame index within its camera (its position in the input where the order is unknown)."""
    return np.arange(obs.n_images) if obs.stream_index is None else np.asarray(obs.stream_index)


def time_checks(clocks: Clocks) -> dict:
    """The timing diagnostics ``sync`` and ``stream-sync`` put in ``rec.info`` (for the quality checks).

    Returns:
        ``clock_residual_px`` (the clock fit's robust reprojection RMS, pixels, or None without the
        refinement), ``noise_px`` (the capture's 2-D noise estimate, :mod:`gttnet.geometry.noise`, pixels, or
        None), ``frame_rates`` (:func:`gttnet.sync.rates.check_rates`'s info: per camera ``given_hz``,
        ``estimated_hz``, ``used_hz``, ``relative``, ``miss_px``...; None when not checked),
        ``cameras_left_out`` (``{camera id: reason}``: no clock, no pose) and ``time_warnings`` (the
        ``warning:`` lines, cameras by id).
    """
    ci = clocks.info
    out = {
        "clock_residual_px": ci.get("rms_px"),
        "noise_px": ci.get("noise_px"),
        "frame_rates": ci.get("rates"),
        "cameras_left_out": dict(ci.get("left_out", {})),
    }
    return {**out, "time_warnings": time_warnings(out)}


def count_rates(cam_id: np.ndarray, top_hz: float = 30.0) -> dict[int, float]:
    """Relative frame rates from image counts: ``top_hz`` times each camera's share of the busiest camera's.

    Right when every camera filmed the same span (only the ratios matter to clock recovery; the offsets
    are then in units of that nominal scale).
    """
    cams, counts = np.unique(np.asarray(cam_id), return_counts=True)
    return {int(c): top_hz * float(k) / float(counts.max()) for c, k in zip(cams, counts, strict=True)}


#: ``stream-sync`` trusts clocks recovered on estimated streams only if their fit's reprojection RMS (the
#: clock refinement's robust RMS) is within this many times what right clocks leave at the capture's noise
#: estimate (:func:`gttnet.sync.streams.expected_clock_rms_px`). On the test captures of docs/METHOD.md's runs
#: of ``benchmarks/bench_stream_sync_sources.py`` (paper walks, CMU, paper at 1 and 5 px, sync recipe) right
#: clocks left 0.88-1.09 times that, the wrong ones 1.43 times and more.
STREAM_SYNC_MAX_RMS_NOISE = 1.3
#: The gate, pixels, where the noise cannot be measured (streams too short), and the former fixed gate.
STREAM_SYNC_MAX_RMS_PX = 3.0
#: Streams whose clocks leave at most this multiple of the expected clock RMS are kept without trying the
#: other order sources: right clocks left 0.88-1.09 times it on the runs quoted above, wrong ones 1.43
#: and more; on the ``val`` half of the out-of-distribution cells (``benchmarks/bench_auto.py``) a far
#: camera rig's right clocks left 1.10-1.12. The costly sources (DLOE's order) are made only when no cheap
#: source's clocks are within the gate (``max_rms_noise``).
STREAM_SYNC_ACCEPT_RMS_NOISE = 1.15


@register_method(
    "stream-sync",
    requires="none",
    summary="no sequencing needed: order each camera's frames by pose, then recover clocks and solve as sync",
)
def reconstruct_stream_sync(
    obs: Observations,
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None = None,
    order_k: int = 32,
    solver: str = "hpf",
    fallback: str | None = "dloe",
    max_rms_px: float | None = None,
    max_rms_noise: float = STREAM_SYNC_MAX_RMS_NOISE,
    order_sources: Sequence[str] | None = None,
    accept_rms_noise: float | None = STREAM_SYNC_ACCEPT_RMS_NOISE,
    order_recs: MutableMapping[str, Reconstruction] | None = None,
) -> Reconstruction:
    """``sync`` on camera streams estimated from the poses, for captures with no timing at all.

    Without sequencing, each camera's frame order is taken from several sources (:mod:`gttnet.sync.streams`:
    the pose graph of the pseudo-triangulated poses, the pseudo-triangulation's partner graph, DLOE's
    recovered order, the root trajectory, and GTT-Net's order where GTT-Net is the fallback or already ran);
    the cameras' clocks are recovered on each, the cheap sources first and DLOE's (a whole reconstruction)
    only when none of them gave right clocks, and the first streams whose clocks leave what right clocks
    leave at the capture's noise (or, failing that, the streams whose clocks explain the images best) are
    kept. Then the high-pass-filter prior solves on the recovered times, as :func:`reconstruct_sync` does.
    Given streams (``partial``, ``full``) are used as they are.

    A wrong order (a periodic motion ordered by pose, a failed pseudo-triangulation) leaves clocks that do
    not explain the images: when the streams were estimated and the kept clocks leave a reprojection RMS
    above ``max_rms_noise`` times what right clocks leave at the capture's noise estimate
    (:func:`gttnet.sync.streams.expected_clock_rms_px`; or ``max_rms_px`` pixels when given), or no
    clocks can be recovered (fewer than two cameras with three images), the ``fallback`` method (an
    order-free one) reconstructs the capture instead.

    Args:
        obs: Observations of any sequencing condition.
        fps: Nominal frame rate per camera; None: estimated from the images (with a warning).
        order_k: Links per image of the pose graph that orders the streams.
        solver: Full-sequencing solver after clock recovery (see :data:`SOLVERS`).
        fallback: Method for estimated streams whose clocks fail the check; None keeps them regardless.
        max_rms_px: A fixed gate on the clocks' reprojection RMS, pixels (None: relative to the noise).
        max_rms_noise: The gate relative to the clock RMS expected at the noise estimate.
        order_sources: Sources of the camera streams (None: :data:`gttnet.sync.streams.ORDER_SOURCES`, plus
            ``gttnet`` when it is the fallback or in ``order_recs``).
        accept_rms_noise: Streams whose clocks leave at most this multiple of the clock RMS expected at the
            noise estimate are kept without trying the remaining sources, and DLOE's order is made only when
            no cheaper source's clocks are within ``max_rms_noise`` (None: every source is tried).
        order_recs: Reconstructions already made of ``obs`` by the order-source methods (``pseudo``,
            ``dloe``, ``gttnet``), by method name: their orders are used as they are, and the ones
            ``stream-sync`` makes are added (``auto`` runs them as candidates too and does not repeat them).

    Returns:
        :func:`reconstruct_sync`'s reconstruction, or the fallback's, in the input's image order. ``info``
        adds ``streams_estimated``, ``clock_rms_px`` (= ``clock_residual_px``), ``gate_px``,
        ``order_source`` (the kept source), ``order_sources`` (per source: ``rms_px``, ``noise_px``,
        ``n_residuals`` or ``error``), :func:`time_checks`'s keys and ``method_ran`` (``stream-sync`` or
        the fallback).
    """
    if obs.sequencing != "none":
        rec = reconstruct_sync(obs, fps=fps, solver=solver)
        given = {"streams_estimated": False, "clock_rms_px": rec.info["clock_residual_px"]}
        return replace(rec, info={**rec.info, **given, "method_ran": "stream-sync"})
    from gttnet.methods import reconstruct

    ran: MutableMapping[str, Reconstruction] = {} if order_recs is None else order_recs
    sources = tuple(order_sources) if order_sources is not None else ORDER_SOURCES
    if order_sources is None and (fallback == "gttnet" or "gttnet" in ran):
        sources += ("gttnet",)
    for name in ("pseudo",):  # the cheapest source: made at once
        if name in sources and name not in ran:
            ran[name] = reconstruct(obs, name)
    given = {k: r.order for k, r in ran.items() if k in sources}
    views = _candidate_views(obs, sources, order_k=order_k, ranks=given)

    def later(name: str) -> Callable[[], Observations | None]:
        def make() -> Observations | None:
            ran[name] = reconstruct(obs, name)
            order = ran[name].order
            return None if order is None else view_from_rank(obs, order)

        return make

    lazy: dict[str, Callable[[], Observations | None]] = {
        k: later(k) for k in ("dloe", "gttnet") if k in sources and k not in given
    }
    choice = choose_streams(
        views,
        fps=fps,
        lazy=lazy,
        accept_rms_noise=accept_rms_noise,
        lazy_rms_noise=None if accept_rms_noise is None else max_rms_noise,
    )
    sigma = choice.noise_px
    gate = max_rms_px if max_rms_px is not None else (
        STREAM_SYNC_MAX_RMS_PX if sigma is None else max_rms_noise * expected_clock_rms_px(sigma)
    )  # fmt: skip
    rms = None if choice.clocks is None else choice.clocks.info.get("rms_px")
    checks: dict = {
        "streams_estimated": True,
        "clock_rms_px": rms,
        "gate_px": gate,
        "order_source": choice.source,
        "order_sources": choice.table,
    }
    if choice.clocks is not None:
        checks.update(time_checks(choice.clocks))
    else:
        checks["noise_px"] = sigma
    if fallback is not None and not (rms is not None and rms <= gate):
        why = f"the clocks leave {rms} px RMS (> {gate:.2f})" if rms is not None else "no clocks recovered"
        log.info("stream-sync: %s; %s instead", why, fallback)
        fb = ran[fallback] if fallback in ran else reconstruct(obs, fallback)
        return replace(fb, info={**fb.info, **checks, "method_ran": fallback})
    if choice.clocks is None:
        errors = "; ".join(f"{k}: {v['error']}" for k, v in choice.table.items() if "error" in v)
        raise GttNetError(f"stream-sync: no camera streams gave clocks ({errors})")
    assert choice.view is not None  # with its clocks
    rec = _timed_solve(choice.view, choice.clocks, frame_times_s=None, solver=solver)
    return replace(rec, info={**rec.info, **checks, "method_ran": "stream-sync"})


def _candidate_views(
    obs: Observations, sources: Sequence[str], *, order_k: int, ranks: Mapping[str, np.ndarray | None]
) -> dict[str, Observations]:
    """One ``partial`` view of the order-free ``obs`` per order source (:mod:`gttnet.sync.streams`)."""
    from gttnet.geometry.candidates import candidate_pseudo_triangulate, use_candidate_search
    from gttnet.geometry.triangulation import pseudo_triangulate
    from gttnet.model.inputs import order_streams

    unknown = sorted(set(sources) - {*ORDER_SOURCES, "gttnet"})
    if unknown:
        raise ValueError(
            f"stream-sync: order sources must be among {(*ORDER_SOURCES, 'gttnet')}, got {unknown}"
        )
    views: dict[str, Observations] = {}
    if "pose-graph" in sources or "root" in sources:
        args = (obs.centers(), obs.rays(), obs.visible, obs.cam_id)
        # above DENSE_MAX_IMAGES the k-d tree candidate search: the exhaustive one is O(N^2 J) in memory
        big = use_candidate_search("none", obs.n_images, "auto")
        x_init = candidate_pseudo_triangulate(*args).X_init if big else pseudo_triangulate(*args).X_init
        if "pose-graph" in sources:
            views["pose-graph"] = order_streams(obs, x_init, k=order_k)
        if "root" in sources:
            views["root"] = view_from_rank(obs, root_rank(x_init))
    for name, rank in ranks.items():
        if rank is not None:
            views[name] = view_from_rank(obs, rank)
    return views


#: What ``auto`` runs under each sequencing condition: the most accurate method of the project's own
#: evaluation (README, "Results" and "Synchronizing cameras after the fact"): with the global order the
#: high-pass-filter prior (3.7 / 4.5 mm against DCT's 6.9 / 5.1 mm, procedural / CMU 01_03, sigma 2 px), with
#: each camera's frame order clock recovery then that prior, with neither ``stream-sync``: each camera's
#: frame order estimated from the poses, then the same, kept only where the recovered clocks explain the
#: images, else the order-free method of :func:`order_free_fallback` (GTT-Net where a bundled model fits).
#: Over the paper, CMU and default validation captures (16 each) the sum of the mean MPJPEs is 539 mm,
#: against 547 for GTT-Net and 583 for DLOE alone. Full sequencing uses time-aware differences, identical
#: to the order-based filter on evenly staggered cameras and right for unequal rates.
AUTO: dict[str, tuple[str, dict]] = {
    "full": ("hpf", {"spacing": "time"}),
    "partial": ("sync", {}),
    "none": ("stream-sync", {}),
}


def order_free_fallback(obs: Observations) -> str:
    """The order-free method ``auto`` falls back on when clocks cannot be recovered.

    GTT-Net wherever a bundled model fits the input's skeleton, else DLOE. Chosen on the validation captures
    by the 2 % rule: for CMU-31, without sequencing, 547 against DLOE's 583 mm (sum of the means over the
    paper, CMU and default validation captures); for any other skeleton the cross-domain model, with its
    DLOE round (and, without sequencing, its camera streams ordered first), on its training families'
    validation captures (humans + hands): without sequencing 61.74 + 3.66 against DLOE's 63.96 + 4.18 mm
    (-4.0 %), with each camera's frame order 30.69 + 3.43 against 54.19 + 4.03 mm.
    """
    from gttdata.skeleton import CMU31_JOINTS
    from gttnet.model.inference import BUNDLED_MODEL, BUNDLED_NONE_MODEL, BUNDLED_POINTNET_MODEL

    if obs.skeleton.joint_names == CMU31_JOINTS:
        bundled = BUNDLED_NONE_MODEL.is_file() or BUNDLED_MODEL.is_file()
    else:
        bundled = BUNDLED_POINTNET_MODEL.is_file()
    return "gttnet" if bundled else "dloe"
