"""The ``sync`` reconstruction method: recover the cameras' clocks, then solve with the timestamps."""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.methods import Reconstruction, register_method
from gttnet.sync.clocks import apply_clocks, clock_times
from gttnet.sync.recover import recover_clocks

__all__ = [
    "AUTO",
    "SOLVERS",
    "STREAM_SYNC_MAX_RMS_PX",
    "count_rates",
    "order_free_fallback",
    "reconstruct_auto",
    "reconstruct_stream_sync",
    "reconstruct_sync",
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
) -> Reconstruction:
    """Clock recovery (:func:`gttnet.sync.recover_clocks`) then a full-sequencing solver on the recovered times.

    Args:
        obs: Observations with each camera's frame order (``partial``; a ``full`` input's timestamps are
            ignored and re-estimated).
        fps: Nominal frame rate per camera (one value, a list by camera id, or ``{camera: Hz}``).
        frame_times_s: Per-image times on each camera's own clock, seconds, shape ``(N,)``.
        max_offset_s: Largest offset searched between two cameras, seconds.
        estimate_drift: Fit per-camera clock drift (None: when a stream spans over 30 s).
        solver: ``"hpf"`` (default: the most accurate full-sequencing solver of the project's evaluation)
            or ``"dct"``.

    Returns:
        Reconstruction in the input's image order; ``order`` ranks the recovered times; ``info`` holds
        ``clock_offsets_s`` ({camera: s}), ``clocks`` (the full table), ``timestamp_s`` (per image, input
        order) and the time spent in each stage.
    """
    from gttnet.methods import reconstruct

    if solver not in SOLVERS:
        raise ValueError(f"sync: solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    t0 = time.perf_counter()
    clocks = recover_clocks(
        obs, fps=fps, frame_times_s=frame_times_s, max_offset_s=max_offset_s, estimate_drift=estimate_drift
    )
    t = clock_times(obs, clocks, frame_times_s=frame_times_s)
    t1 = time.perf_counter()
    inner = reconstruct(apply_clocks(obs, clocks, frame_times_s=frame_times_s), solver, **SOLVERS[solver])
    seq = np.argsort(t, kind="stable")
    X = np.empty_like(inner.points3d)
    X[seq] = inner.points3d
    rank = np.empty(obs.n_images, dtype=np.int64)
    rank[seq] = np.arange(obs.n_images)
    return Reconstruction(
        points3d=X,
        order=rank,
        info={
            "clock_offsets_s": {
                str(int(c)): float(o) for c, o in zip(clocks.cameras, clocks.offset_s, strict=True)
            },
            "clocks": clocks.to_dict(),
            "timestamp_s": t.tolist(),
            "solver": solver,
            "solver_info": inner.info,
            "sync_seconds": t1 - t0,
            "solve_seconds": inner.seconds,
        },
    )


def count_rates(cam_id: np.ndarray, top_hz: float = 30.0) -> dict[int, float]:
    """Relative frame rates from image counts: ``top_hz`` times each camera's share of the busiest camera's.

    Right when every camera filmed the same span (only the ratios matter to clock recovery; the offsets
    are then in units of that nominal scale).
    """
    cams, counts = np.unique(np.asarray(cam_id), return_counts=True)
    return {int(c): top_hz * float(k) / float(counts.max()) for c, k in zip(cams, counts, strict=True)}


#: ``stream-sync`` trusts clocks recovered on estimated streams only if they explain the images to within this
#: reprojection RMS (pixels; the clock refinement's robust RMS). On the validation captures of the paper, CMU
#: and default recipes, where the estimated streams beat GTT-Net the clocks mostly left 0.9-2.4 px, where
#: they lost mostly 3-19 px; limits of 2.5-4 px scored the same. Above it, the fallback method runs instead.
STREAM_SYNC_MAX_RMS_PX = 3.0


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
    max_rms_px: float = STREAM_SYNC_MAX_RMS_PX,
) -> Reconstruction:
    """``sync`` on camera streams estimated from the poses, for captures with no timing at all.

    Without sequencing, each camera's frames are put in the order of the spectral order of a pose graph
    over the pseudo-triangulated poses (:func:`gttnet.model.inputs.order_streams`, ``order_k`` links per
    image; within one camera consecutive frames lie several global images apart, so this per-camera order
    is far more often right than the global one). Then the cameras' clocks are recovered and the
    high-pass-filter prior solves on the recovered times, as :func:`reconstruct_sync` does. Given streams
    (``partial``, ``full``) are used as they are.

    Works where the motion does not come back to the same poses: a periodic motion (walking on the spot)
    or a failed pseudo-triangulation leaves the per-camera order wrong, and the smoothness prior then ties
    together moments that are not neighbours. Such clocks do not explain the images: when the streams were
    estimated and the recovered clocks leave a reprojection RMS above ``max_rms_px``, or the clocks cannot be
    recovered at all (a camera with fewer than three images), the ``fallback`` method (an order-free one)
    reconstructs the capture instead (README, "Synchronizing cameras after the
    fact", has the validation numbers).

    Args:
        obs: Observations of any sequencing condition.
        fps: Nominal frame rate per camera; None: :func:`count_rates` (the cameras are assumed to film the
            same span).
        order_k: Links per image of the pose graph that orders the streams.
        solver: Full-sequencing solver after clock recovery (see :data:`SOLVERS`).
        fallback: Method for estimated streams whose clocks fail the check; None keeps them regardless.
        max_rms_px: The check's largest reprojection RMS of the recovered clocks, pixels.

    Returns:
        :func:`reconstruct_sync`'s reconstruction, or the fallback's, in the input's image order. ``info``
        adds ``streams_estimated``, ``clock_rms_px`` and ``method_ran`` (``stream-sync`` or the fallback).
    """
    from gttnet.geometry.candidates import candidate_pseudo_triangulate, use_candidate_search
    from gttnet.geometry.triangulation import pseudo_triangulate
    from gttnet.model.inputs import order_streams

    view = obs
    if obs.sequencing == "none":
        args = (obs.centers(), obs.rays(), obs.visible, obs.cam_id)
        # above DENSE_MAX_IMAGES the k-d tree candidate search: the exhaustive one is O(N^2 J) in memory
        big = use_candidate_search("none", obs.n_images, "auto")
        x_init = candidate_pseudo_triangulate(*args).X_init if big else pseudo_triangulate(*args).X_init
        view = order_streams(obs, x_init, k=order_k)
    checked = obs.sequencing == "none" and fallback is not None  # only estimated streams are checked
    rec: Reconstruction | None = None
    why = ""
    try:
        rec = reconstruct_sync(view, fps=count_rates(obs.cam_id) if fps is None else fps, solver=solver)
    except GttNetError as exc:  # e.g. a camera with too few images for clock recovery
        if not checked:
            raise
        why = str(exc)
    rms = None if rec is None else rec.info["clocks"].get("info", {}).get("rms_px")
    checks = {"streams_estimated": obs.sequencing == "none", "clock_rms_px": rms}
    if checked and not (rms is not None and rms <= max_rms_px):  # rec None: rms None too
        from gttnet.methods import reconstruct

        assert fallback is not None  # checked implies it
        why = why or f"the clocks leave {rms} px RMS (> {max_rms_px:g})"
        log.info("stream-sync: %s; %s instead", why, fallback)
        fb = reconstruct(obs, fallback)
        return replace(fb, info={**fb.info, **checks, "method_ran": fallback})
    assert rec is not None  # without a check, a failed recovery was raised above
    return replace(rec, info={**rec.info, **checks, "method_ran": "stream-sync"})


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


@register_method(
    "auto",
    requires="none",
    summary="the most accurate method for the input's sequencing: hpf (full), sync (partial), stream-sync (none)",
)
def reconstruct_auto(
    obs: Observations,
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None = None,
    frame_times_s: np.ndarray | None = None,
) -> Reconstruction:
    """Run the method :data:`AUTO` picks for ``obs.sequencing``.

    Args:
        obs: Observations of any sequencing condition.
        fps: Nominal per-camera rates, passed to ``sync`` and ``stream-sync`` (unused under ``full``).
        frame_times_s: Per-image times on each camera's clock, passed to ``sync``.

    Returns:
        The chosen method's reconstruction; ``info["method_ran"]`` names it. Under ``partial``, where the
        clocks cannot be recovered, :func:`order_free_fallback`'s method runs instead, with the reason in
        ``info["sync_failed"]``.
    """
    from gttnet.methods import reconstruct

    name, options = AUTO[obs.sequencing]
    if name == "sync":
        options = {**options, "fps": fps, "frame_times_s": frame_times_s}
    elif name == "stream-sync":
        options = {**options, "fps": fps, "fallback": order_free_fallback(obs)}
    try:
        rec = reconstruct(obs, name, **options)
    except GttNetError as exc:
        if name != "sync":
            raise
        # Clocks that cannot be recovered (e.g. a camera with fewer than three images): the order-free
        # method still uses each camera's frame order (neighbourhoods and chain), as stream-sync's does.
        name = order_free_fallback(obs)
        log.warning("auto: clock recovery failed (%s); %s reconstructs the capture instead", exc, name)
        rec = reconstruct(obs, name)
        rec = replace(rec, info={**rec.info, "sync_failed": str(exc)})
    return replace(rec, info={**rec.info, "method_ran": rec.info.get("method_ran", name)})
