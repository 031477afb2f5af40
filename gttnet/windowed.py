"""Windowed reconstruction of long recordings: overlapping time windows, each solved alone, stitched.

Every method's cost grows with the square of the image count (pairwise pseudo-triangulation, an
``N x N`` affinity, a structure solve over all images), so a 10-minute capture of 4 cameras at 30 Hz
(72,000 images) cannot be solved in one piece. Under ``partial`` and ``full`` sequencing the images can
be placed roughly in time, so the recording is cut into overlapping windows, each window is
reconstructed with the chosen method as an ordinary capture of the same sequencing condition, and the
windows are blended in their overlaps. Time and memory are then linear in the number of images.
Without sequencing the windows follow the poses' own order instead (:func:`pose_times`, from sparse
neighbour searches only), so memory and time grow as N log N there too.

Placing images in time (:func:`approximate_times`):

* ``full``: the timestamps.
* ``partial``: the streams' relative timing is unknown, only each stream's own order. The cameras'
  clocks are recovered from the skeletons over the whole recording (:func:`gttnet.sync.recover_clocks`),
  and every image is placed by those clocks (:func:`synced_times`). Long recordings are recovered
  piecewise, in time linear in their length: the full offset search on the first 20 s, then offsets
  and clock drift from windows spread over the whole recording, so a clock-rate error (100 ppm is 60 ms,
  two frames at 30 Hz, after 10 minutes) is followed to the end (``benchmarks/bench_sync_long.py``).
  ``sync`` windows (and ``auto``'s, once it chose ``sync`` on the first window) then solve on those
  recording-wide clocks instead of recovering their own (re-fitting clocks in every window took about
  40 % of a long recording's run); the stitched
  result reports them (``clock_offsets_s`` and the timing checks). Each window's HPF prior weight is
  cross-validated starting from the previous window's (:func:`_warm_start`).
  If clock recovery fails, images are placed at their stream's elapsed fraction, ``(rank in stream +
  0.5) / images in stream`` (:func:`approximate_times`), which assumes streams spanning the same
  recording at the same rate.

Window length (``window="auto"``, :func:`auto_window`): ``80 V`` images (320 for 4 cameras, ~2.7 s
at 30 Hz each) with a quarter of it as overlap. That is the length the bundled GTT-Net model and the
DLOE defaults were tuned on (~300-image sequences), every image keeps its K = 20 neighbours within the
window, and the per-window quadratic cost stays a fraction of a second. Captures of at most
:data:`AUTO_MIN_IMAGES` images are solved in one piece; ``benchmarks/bench_windowed.py`` compares
windowed and unwindowed accuracy.

Stitching: inside a window, an image's weight rises linearly over the first ``overlap`` images and
falls over the last ``overlap`` (full weight elsewhere and at the recording's ends); each image's
joints are the weighted mean of its windows' estimates. The recovered order is the image's rank within
the window where its weight is largest, offset by that window's start (windows' local orders, from
their affinities, are flipped to agree with the approximate times).
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass

import numpy as np

from gttdata.capture.views import Observations
from gttnet.methods import Reconstruction, blank_unobserved, check_sequencing, method_spec

__all__ = [
    "AUTO_MIN_IMAGES",
    "pose_times",
    "synced_times",
    "WindowPlan",
    "approximate_times",
    "auto_window",
    "plan_windows",
    "reconstruct_windowed",
    "subset_observations",
]

log = logging.getLogger(__name__)

#: ``window="auto"`` solves captures of at most this many images in one piece.
AUTO_MIN_IMAGES = 2000

#: Images per camera in an automatic window.
_PER_CAMERA = 80

#: Without sequencing, automatic windows are this many times longer: a window along the poses' order is a
#: cluster of similar poses from all over the recording, not a stretch of time, and a longer one keeps more of
#: the links a whole-capture solve would make. On the 7,200-image long.yaml capture (``--sequencing none``,
#: ``--method auto``) windows of 1,280 images gave 14.05 mm against 14.63 mm with 320 and 13.86 mm in one
#: piece, at the same CPU time and peak memory (0.5 GB, against 1.65 GB in one piece).
_NONE_FACTOR = 4


@dataclass(frozen=True)
class WindowPlan:
    """Overlapping windows over N images.

    Args:
        order: Images sorted by approximate time, shape ``(N,)`` int64.
        starts: First position (in ``order``) of each window, shape ``(W,)`` int64.
        length: Images per window (the last window may be shorter only when N is).
        overlap: Images shared by consecutive windows (at least; the last window is aligned to the end).
    """

    order: np.ndarray
    starts: np.ndarray
    length: int
    overlap: int

    def __len__(self) -> int:
        return int(self.starts.shape[0])

    def window(self, w: int) -> np.ndarray:
        """Image indices of window ``w`` in approximate time order, shape ``(<= length,)``."""
        s = int(self.starts[w])
        return self.order[s : s + self.length]

    def weights(self, w: int) -> np.ndarray:
        """Blending weight of each image of window ``w`` (linear ramps over the overlaps), in (0, 1]."""
        s = int(self.starts[w])
        m = min(self.length, self.order.shape[0] - s)
        pos = np.arange(m, dtype=np.float64)
        ramp = float(self.overlap + 1)
        up = np.ones(m) if w == 0 else np.minimum(1.0, (pos + 1.0) / ramp)
        down = np.ones(m) if w == len(self) - 1 else np.minimum(1.0, (m - pos) / ramp)
        return np.minimum(up, down)


def approximate_times(obs: Observations) -> np.ndarray:
    """A rough time of each image, for cutting windows (see the module docstring), shape ``(N,)``.

    Returns seconds under ``full`` and the stream's elapsed fraction in ``[0, 1)`` under ``partial``.

    Raises:
        ValueError: Under ``none`` sequencing (no time information).
    """
    if obs.sequencing == "full":
        return np.asarray(obs.timestamp_s, dtype=np.float64)
    if obs.sequencing != "partial":
        raise ValueError("windowed reconstruction needs 'partial' or 'full' sequencing (image order in time)")
    cam = np.asarray(obs.cam_id)
    order = np.lexsort((np.asarray(obs.stream_index), cam))
    t = np.empty(cam.shape[0])
    for c in np.unique(cam):
        idx = order[cam[order] == c]
        t[idx] = (np.arange(idx.size) + 0.5) / idx.size
    return t


def synced_times(obs: Observations) -> np.ndarray:
    """Capture time of every image from clocks recovered over the whole recording, seconds, shape ``(N,)``.

    :func:`gttnet.sync.recover_clocks` (nominal 30 Hz; piecewise and linear in N on long recordings,
    with drift over 30 s) times every image (:func:`gttnet.sync.clock_times`).

    Raises:
        GttNetError: If clock recovery fails (e.g. a single camera).
        SequencingError: Without stream order.
    """
    from gttnet.sync import clock_times, recover_clocks

    return clock_times(obs, recover_clocks(obs))


def pose_times(obs: Observations, *, k: int = 16) -> np.ndarray:
    """Where each image of an order-free capture falls in the poses' own order, shape ``(N,)`` (ranks).

    Without sequencing nothing times the images, so windows are cut along the spectral order of the
    k-nearest-neighbour graph over the pseudo-triangulated poses (the order GTT-Net and ``stream-sync``
    derive under ``none``). Every step is sparse: the k-d tree candidate search
    (:func:`gttnet.geometry.candidates.candidate_pseudo_triangulate`), a k-nearest-neighbour pose graph and
    a Lanczos Fiedler vector, so memory and time grow as N log N; an image's window then holds the images
    whose poses are nearest in that order, which are the neighbours a whole-capture solve would link.
    """
    from gttnet.geometry.candidates import candidate_pseudo_triangulate
    from gttnet.geometry.ordering import pose_graph_affinity, spectral_order

    x = candidate_pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id).X_init
    A = pose_graph_affinity(np.nan_to_num(np.asarray(x, dtype=np.float64)), k=k, sparse=True)
    return np.asarray(spectral_order(A), dtype=np.float64)


def auto_window(obs: Observations) -> tuple[int, int]:
    """``(length, overlap)`` of automatic windows: ``80 V`` images for V cameras, a quarter overlapping.

    Without sequencing ``320 V`` (:data:`_NONE_FACTOR`).
    """
    v = max(int(np.unique(obs.cam_id).size), 1)
    length = _PER_CAMERA * v * (_NONE_FACTOR if obs.sequencing == "none" else 1)
    return length, length // 4


def plan_windows(times: np.ndarray, length: int, overlap: int) -> WindowPlan:
    """Cut images sorted by ``times`` into windows of ``length`` with at least ``overlap`` shared.

    Args:
        times: Approximate time per image, shape ``(N,)``.
        length: Images per window (>= 2).
        overlap: Images shared by consecutive windows, ``0 <= overlap < length``.

    Example:
        >>> plan_windows(np.arange(10.0), 4, 1).starts.tolist()
        [0, 3, 6]
    """
    if length < 2 or not 0 <= overlap < length:
        raise ValueError(f"window length must be >= 2 and 0 <= overlap < length, got {length} and {overlap}")
    n = int(np.shape(times)[0])
    order = np.argsort(np.asarray(times), kind="stable").astype(np.int64)
    if n <= length:
        return WindowPlan(order=order, starts=np.zeros(1, dtype=np.int64), length=length, overlap=overlap)
    stride = length - overlap
    starts = list(range(0, n - length + 1, stride))
    if starts[-1] + length < n:
        starts.append(n - length)
    return WindowPlan(order=order, starts=np.asarray(starts, dtype=np.int64), length=length, overlap=overlap)


def subset_observations(obs: Observations, idx: np.ndarray) -> tuple[Observations, np.ndarray]:
    """The images ``idx`` as a capture of their own, in the order the sequencing condition prescribes.

    Returns:
        ``(observations, rows)``: the sub-capture and, for each of its images, the index in ``obs``.
    """
    idx = np.asarray(idx, dtype=np.int64)
    if obs.sequencing == "partial":
        assert obs.stream_index is not None  # a partial view carries its stream order
        rows = idx[np.lexsort((obs.stream_index[idx], obs.cam_id[idx]))]
    elif obs.sequencing == "full":
        assert obs.timestamp_s is not None  # a full view carries its timestamps
        rows = idx[np.argsort(obs.timestamp_s[idx], kind="stable")]
    else:
        rows = np.sort(idx)
    return obs.take(rows), rows


def _local_rank(rec: Reconstruction, t_local: np.ndarray) -> np.ndarray:
    """Rank of each window image in time: the method's order (else its affinity's), else ``t_local``."""
    n = t_local.shape[0]
    order = rec.order
    if order is None and rec.affinity is not None:
        from gttnet.geometry.ordering import spectral_order

        try:
            order = spectral_order(rec.affinity)
        except Exception as exc:  # a disconnected window affinity: fall back to the rough times
            log.debug("window order from approximate times (%s)", exc)
            order = None
    t_rank = np.empty(n, dtype=np.int64)
    t_rank[np.argsort(t_local, kind="stable")] = np.arange(n)
    if order is None:
        return t_rank
    order = np.asarray(order, dtype=np.int64)
    if np.corrcoef(order, t_rank)[0, 1] < 0:
        order = n - 1 - order
    return order


#: Options of ``sync`` that shape clock recovery (the recording's clocks are recovered with them once).
_CLOCK_OPTIONS = ("fps", "frame_times_s", "max_offset_s", "estimate_drift")


def _recording_clocks(obs: Observations, method: str, options: dict):
    """Clocks of the whole recording (:func:`gttnet.sync.recover_clocks`), with the method's clock options.

    ``sync`` and ``auto`` windows pass ``fps`` and ``frame_times_s`` (and ``sync`` its search options);
    other methods' options are not clock options and are left out.

    Raises:
        GttNetError: If clock recovery fails (e.g. a single camera).
    """
    from gttnet.sync import recover_clocks

    keep = _CLOCK_OPTIONS if method in ("sync", "auto") else ()
    return recover_clocks(obs, **{k: v for k, v in options.items() if k in keep})


def _clock_times(obs: Observations, clocks, options: dict) -> np.ndarray:
    """Every image's time under the recording's clocks (with ``frame_times_s`` when given), seconds, ``(N,)``."""
    from gttnet.sync import clock_times

    return clock_times(obs, clocks, frame_times_s=options.get("frame_times_s"))


def _warm_start(method: str, opts: dict, prev: Reconstruction | None) -> dict:
    """Options that start a window's prior-weight search at the previous window's choice.

    HPF's weight (alone or as ``sync``'s solver) is cross-validated in every window; starting at the
    neighbour's weight (``lam_start``, :func:`gttnet.baselines.highpass.reconstruct_hpf`) scores 3 weights
    instead of 9 where the motion's character has not changed, and follows it where it has.
    """
    if prev is None:
        return {}
    if method == "hpf" and opts.get("lam") is None and "lam" in prev.info:
        return {"lam_start": float(prev.info["lam"])}
    lam = (prev.info.get("solver_info") or {}).get("lam")
    if method == "sync" and prev.info.get("solver", "hpf") == "hpf" and lam is not None:
        return {"solver_options": {**(opts.get("solver_options") or {}), "lam_start": float(lam)}}
    return {}


def _clock_info(clocks) -> dict:
    """The recording's clocks in the stitched result's ``info``: offsets and the timing checks, as ``sync``'s."""
    from gttnet.sync.method import time_checks

    offsets = {str(int(c)): float(o) for c, o in zip(clocks.cameras, clocks.offset_s, strict=True)}
    return {"clock_offsets_s": offsets, **time_checks(clocks)}


def _auto_winner(obs: Observations, rec, options: dict) -> tuple:
    """``auto`` selects on the first window only; its winner, with its options, solves the others (linear time).

    Returns:
        ``(spec, options, info)``: the winner's registry entry, its options over the whole capture and the
        ``method_ran`` / ``auto`` entries for the stitched result's ``info``.
    """
    from gttnet.auto import candidates

    ran = rec.info["auto"]["ran"]
    opts = next(o for m, o in candidates(obs, **options) if m == ran)
    auto = {**rec.info["auto"], "why": rec.info["auto"]["why"] + " (selected on the first window)"}
    return method_spec(ran), opts, {"method_ran": ran, "auto": auto}


def reconstruct_windowed(
    obs: Observations,
    method: str,
    *,
    window: int | str = "auto",
    overlap: int | None = None,
    times: np.ndarray | None = None,
    progress: bool = False,
    **options,
) -> Reconstruction:
    """Reconstruct a long capture window by window with a registered method, then stitch the windows.

    Args:
        obs: Observations of any sequencing; under ``none`` the windows follow :func:`pose_times`.
        method: Registered method name.
        window: Images per window, or ``"auto"`` (:func:`auto_window`, and one piece for captures of at
            most :data:`AUTO_MIN_IMAGES` images).
        overlap: Images shared by consecutive windows (default: a quarter of the window).
        times: Approximate time of each image, shape ``(N,)`` (e.g. from a clocks file); default: the
            timestamps under ``full``, :func:`synced_times` under ``partial`` (falling back to
            :func:`approximate_times` when clock recovery fails), :func:`pose_times` under ``none``.
        progress: Show a progress bar with ETA on stderr.
        **options: Options of the method.

    Returns:
        The stitched reconstruction: ``points3d`` (N, J, 3), ``order`` (N,), no affinity (it would be
        ``N x N``); ``info`` holds the windows' count, length and overlap.
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    spec = method_spec(method)
    check_sequencing(obs, spec)
    n = obs.n_images
    if window == "auto":
        if n <= AUTO_MIN_IMAGES:
            from gttnet.methods import reconstruct

            return reconstruct(obs, method, **options)
        length, auto_overlap = auto_window(obs)
    else:
        length, auto_overlap = int(window), int(window) // 4
    ov = auto_overlap if overlap is None else int(overlap)
    clock = "given"
    clocks = None
    if times is not None:
        t_hat = np.asarray(times, dtype=np.float64)
    elif obs.sequencing == "partial":
        from gttnet.errors import GttNetError

        try:
            clocks = _recording_clocks(obs, method, options)
            t_hat, clock = _clock_times(obs, clocks, options), "recovered clocks"
        except GttNetError as exc:
            log.warning("clock recovery failed (%s); windows follow each stream's elapsed fraction", exc)
            t_hat, clock = approximate_times(obs), "stream fraction"
    elif obs.sequencing == "none":
        t_hat, clock = pose_times(obs), "pose order"
    else:
        t_hat, clock = approximate_times(obs), "timestamps"
    if t_hat.shape != (n,):
        raise ValueError(f"times must have shape ({n},), got {t_hat.shape}")
    plan = plan_windows(t_hat, length, ov)
    t_win, cpu_win = time.perf_counter(), time.process_time()
    cpu_solve = 0.0
    from tqdm import tqdm

    X = np.zeros((n, obs.n_joints, 3))
    wsum = np.zeros((n, obs.n_joints))
    best_w = np.full(n, -1.0)
    key = np.zeros(n)
    bar = tqdm(
        total=n,
        unit="img",
        desc=f"{method} windows",
        disable=not progress,
        file=sys.stderr,
        dynamic_ncols=True,
    )
    done = 0
    info_auto: dict = {}
    rec = None
    for w in range(len(plan)):
        sub, rows = subset_observations(obs, plan.window(w))
        # Per-image options (e.g. frame_times_s) follow the window's images.
        opts = {
            k: v[rows] if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == n else v
            for k, v in options.items()
        }
        if clocks is not None and spec.name == "sync":
            opts["clocks"] = clocks  # the recording's clocks: no recovery per window
        opts.update(_warm_start(spec.name, opts, rec if w else None))
        c0 = time.process_time()
        rec = spec.fn(sub, **opts)
        cpu_solve += time.process_time() - c0
        if w == 0 and method == "auto":
            spec, options, info_auto = _auto_winner(obs, rec, options)
        win = plan.window(w)
        srt = np.argsort(win)
        weight = plan.weights(w)[srt[np.searchsorted(win[srt], rows)]]
        P = np.asarray(rec.points3d)
        ok = np.isfinite(P).all(axis=-1)  # a joint a window left NaN (e.g. HPF: too few rays) is not blended
        X[rows] += np.where(ok[..., None], weight[:, None, None] * P, 0.0)
        wsum[rows] += weight[:, None] * ok
        rank = _local_rank(rec, t_hat[rows])
        better = weight > best_w[rows]
        key[rows[better]] = plan.starts[w] + rank[better]
        best_w[rows[better]] = weight[better]
        new = int(min(plan.starts[w] + plan.length, n) - done) if w < len(plan) - 1 else n - done
        bar.update(max(new, 0))
        done += max(new, 0)
    bar.close()
    with np.errstate(invalid="ignore", divide="ignore"):
        X = np.where((wsum > 0)[..., None], X / wsum[..., None], np.nan)
    order = np.empty(n, dtype=np.int64)
    order[np.lexsort((t_hat, key))] = np.arange(n)
    info = {
        "windows": len(plan),
        "window": plan.length,
        "overlap": plan.overlap,
        "clock": clock,
        "seconds_per_window": (time.perf_counter() - t_win) / len(plan),
        # CPU seconds of this process by stage: placing the images (clocks), the windows' solves, and
        # the rest (cutting, sub-captures, stitching)
        "cpu_seconds": {
            "clocks": cpu_win - cpu0,
            "solve": cpu_solve,
            "windows": time.process_time() - cpu_win - cpu_solve,
        },
    }
    info.update(info_auto)
    if clocks is not None:
        info.update(_clock_info(clocks))
    rec = Reconstruction(
        points3d=X,
        affinity=None,
        order=order,
        seconds=time.perf_counter() - t0,
        method=method,
        sequencing=obs.sequencing,
        info=info,
    )
    return blank_unobserved(rec, obs)
