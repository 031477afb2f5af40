"""The ``auto`` method: run the candidates the input's sequencing allows, keep the best by self-assessment.

The candidates (:func:`candidates`) come most-informed first: with the global order the high-pass-filter
prior on the timestamps, then clock recovery on the streams, then the order-free methods; with each
camera's frame order clock recovery, then the order-free ones; with neither the GTT-Net model where a
bundled one fits the skeleton (the cheapest), ``stream-sync`` (streams ordered by pose, clocks recovered),
DLOE and the pseudo-triangulation. Work is shared: ``stream-sync`` takes its camera streams from the
GTT-Net reconstruction already made, and makes DLOE's only when the cheaper order sources give no clocks
within its gate; where GTT-Net cannot run, that DLOE reconstruction is the ``dloe`` candidate, not made
again. DLOE and the pseudo-triangulation are not candidates once GTT-Net (or, for the latter, DLOE) has
run (:data:`SUBSUMED_BY`).

Each reconstruction carries its self-assessment (:mod:`gttnet.quality`, ``info["quality"]``), raised
without sequencing where ``stream-sync`` and an order-free candidate disagree by more than their expected
errors allow, and with real timing biased towards the most informed candidate. ``auto`` stops as soon as
the best candidate's evidence is decisive (its reprojection residual at the capture's own noise floor, its
held-out prediction error within the noise, and no image without observations left to guess: nothing can
do clearly better; without any sequencing only after a second, independent candidate agreed), lists the
candidates it did not run as ``skipped`` with the reason, and otherwise returns the candidate with the
smallest ``expected_error_mm``.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from gttdata.capture.views import Observations
from gttnet.errors import GttNetError
from gttnet.methods import Reconstruction, register_method

__all__ = [
    "ORDER_METHODS",
    "TIMED",
    "STOP_EXCESS",
    "SUBSUMED_BY",
    "STOP_HOLDOUT",
    "candidates",
    "decisive",
    "reconstruct_auto",
]

log = logging.getLogger(__name__)

#: A candidate is decisive when its reprojection residual is at most this multiple of the capture's noise...
STOP_EXCESS = 1.3
#: ... and its held-out prediction error at most this multiple of the noise at the joints' depth (mm/mm),
STOP_HOLDOUT = 1.1
#: ... and at most this share of its expected error from what the medians cannot see (:func:`_hidden_mm`).
STOP_HIDDEN = 0.5


#: Candidates run before a decisive one may stop the search, by sequencing: without any, the clocks rest
#: on estimated streams, and only an independent reconstruction can show them wrong (:func:`_agreement`).
MIN_TRIED = {"none": 2}
#: How much timing each candidate's result rests on: a disagreement is put on the more informed one.
INFORMED = {"hpf": 3, "sync": 2, "stream-sync": 2, "gttnet": 1, "dloe": 1, "pseudo": 0}


def _own_expected(q: Mapping[str, Any]) -> float:
    """A candidate's expected error before the disagreement bound of :func:`_agreement`, mm."""
    return float(q.get("own_expected_error_mm", q["expected_error_mm"]))


def _requalified(
    rec: Reconstruction, q: dict[str, Any], row: dict[str, Any], unc: np.ndarray | None
) -> Reconstruction:
    """``rec`` with the self-assessment ``q`` and per-point uncertainty ``unc``; its report ``row`` follows."""
    row["expected_error_mm"] = q["expected_error_mm"]
    row["reasons"] = list(q["reasons"])
    return replace(rec, info={**rec.info, "quality": q}, uncertainty_mm=unc)


def _scaled(unc: np.ndarray | None, raised: float, own: float) -> np.ndarray | None:
    """The per-point uncertainty ``unc`` scaled as the expected error went from ``own`` to ``raised``."""
    return unc if unc is None or own <= 0 else unc * (raised / own)


def _agreement(recs: list[Reconstruction], rows: list[dict[str, Any]]) -> list[Reconstruction]:
    """Raise each candidate's expected error to what its disagreement with the less-informed ones implies.

    Two reconstructions ``a`` and ``b`` a mean distance ``D`` apart cannot both be close to the truth:
    ``MPJPE(a) >= D - MPJPE(b)``. With ``b``'s expected error for ``MPJPE(b)``, a candidate's expected error
    becomes at least ``D - expected(b)`` over the less-informed candidates ``b`` (:data:`INFORMED`;
    agreement between independent methods). The disagreement is put on the more-informed candidate: it rests on more
    assumptions (clocks, estimated streams) that the images cannot always check, while the order-free
    ones' own evidence (held-out images) measures their depth errors directly. ``rows`` (the ``auto``
    report's candidate entries, in the same order) are updated alike.
    """
    if len(recs) < 2:
        return recs
    own = [_own_expected(r.info["quality"]) for r in recs]
    out = []
    for i, a in enumerate(recs):
        bound, other = 0.0, ""
        for b in recs:
            if INFORMED.get(b.method, 0) >= INFORMED.get(a.method, 0):
                continue
            d = 1000.0 * np.linalg.norm(a.points3d - b.points3d, axis=-1)
            dist = float(np.nanmean(d)) if np.isfinite(d).any() else 0.0
            own_b = _own_expected(b.info["quality"])
            if dist - own_b > bound:
                bound, other = dist - own_b, b.info.get("method_ran", b.method)
        q = {**a.info["quality"], "own_expected_error_mm": own[i]}
        q["expected_error_mm"] = round(max(own[i], bound), 3)
        q["reasons"] = [x for x in q["reasons"] if not x.startswith("disagrees")]
        if bound > own[i]:
            q["reasons"].append(
                f"disagrees with {other} by more than their expected errors allow: at least {bound:.1f} mm"
            )
        unc = _scaled(a.uncertainty_mm, q["expected_error_mm"], own[i])
        out.append(_requalified(a, q, rows[i], unc))
    return out


#: A candidate whose own noise estimate exceeds the capture's smallest by this factor is re-assessed at it.
NOISE_SPREAD = 1.25


def _common_noise(
    obs: Observations, recs: list[Reconstruction], rows: list[dict[str, Any]]
) -> list[Reconstruction]:
    """Re-assess, along the capture's best-ordered streams, the candidates whose own order reads noisier.

    Without sequencing each candidate's self-assessment reads the noise, the roughness and the held-out
    error along the order it recovered; a wrong order inflates all three (a quadruped turning at 10 Hz:
    35-73 px of noise for DLOE's and GTT-Net's orders at 2.6 px), although the per-image poses may be
    good. The noise is one property of the capture, and a wrong order only adds to it: the candidate
    whose order reads the least noise gives the time axis, and a candidate reading more than
    :data:`NOISE_SPREAD` times that is re-assessed along it (:func:`gttnet.quality.assess`). ``rows``
    (the report's candidate entries, same order) are updated alike.
    """
    from gttnet.quality import assess

    def own(r: Reconstruction) -> float:  # the noise read along the candidate's own order
        q = r.info.get("quality", {})
        s = q.get("order_noise_px", q.get("sigma_px"))
        return float("inf") if s is None or r.order is None else float(s)

    ref = min(recs, key=own)
    sigma = own(ref)
    if not np.isfinite(sigma):
        return recs
    out = []
    for i, r in enumerate(recs):
        if own(r) <= NOISE_SPREAD * sigma:
            out.append(r)
            continue
        quality, unc = assess(obs, r, noise_px=sigma, order=ref.order)
        quality["order_noise_px"] = round(own(r), 4)
        quality["reasons"].append(
            f"read along {ref.info.get('method_ran', ref.method)}'s order: its own reads {own(r):.1f} px "
            f"of noise, that one {sigma:.2f} px"
        )
        out.append(_requalified(r, quality, rows[i], unc))
    return out


#: Weight of the clock-fit excess (mm) in the expected error of clocks recovered on estimated streams, chosen
#: on the val half of the out-of-distribution cells (22 captures without sequencing, 2026-12-06; 1.5-2.1 keep
#: stream-sync on the 1 px walks, where its clocks leave 1.4-1.7x the expected RMS but it is 2x better than
#: GTT-Net, and hand the 25 Hz and mixed-rate captures whose clocks leave 1.8-2x to GTT-Net).
CLOCK_EXCESS_FACTOR = 1.75


def _clock_excess(recs: list[Reconstruction], rows: list[dict[str, Any]]) -> list[Reconstruction]:
    """Charge clocks recovered on estimated streams for the residual right clocks would not leave.

    Right clocks leave a clock-fit RMS of about :func:`gttnet.sync.streams.expected_clock_rms_px` at the
    capture's noise; what the fit leaves beyond that (in quadrature, pixels, times the capture's mm per
    pixel and :data:`CLOCK_EXCESS_FACTOR`) is added in quadrature to the candidate's expected error. The
    reprojection residual of the final solve cannot show it: the high-pass prior absorbs slightly wrong
    clocks into smooth but displaced trajectories (25 Hz captures: 34 mm where GTT-Net gave 16).
    ``rows`` (the report's candidate entries, same order) are updated alike.
    """
    from gttnet.sync.streams import expected_clock_rms_px

    out = []
    for i, r in enumerate(recs):
        q = r.info.get("quality", {})
        rms, sigma, noise_mm = r.info.get("clock_rms_px"), q.get("sigma_px"), q.get("noise_mm")
        if (
            not r.info.get("streams_estimated")
            or "clock_excess_mm" in q
            or rms is None
            or not sigma
            or noise_mm is None
        ):
            out.append(r)
            continue
        right = expected_clock_rms_px(float(sigma))
        excess_px = float(np.sqrt(max(float(rms) ** 2 - right**2, 0.0)))
        excess_mm = CLOCK_EXCESS_FACTOR * excess_px * float(noise_mm) / float(sigma)
        own = _own_expected(q)
        raised = round(float(np.hypot(own, excess_mm)), 3)
        q = {**q, "clock_excess_mm": round(excess_mm, 3), "expected_error_mm": raised}
        q["own_expected_error_mm"] = raised
        if excess_mm > own:
            q["reasons"] = [
                *q.get("reasons", []),
                f"the clock fit leaves {float(rms):.2f} px where right clocks leave "
                f"{right:.2f} px: {excess_mm:.1f} mm added",
            ]
        out.append(_requalified(r, q, rows[i], _scaled(r.uncertainty_mm, raised, own)))
    return out


#: With real timing (timestamps, or each camera's frame order) a less informed candidate replaces the most
#: informed one only when its expected error is smaller by this factor: two predictions' log errors differ
#: with a spread of about 0.3 (the calibration's log residual std 0.22, twice), so smaller gaps are noise.
#: Without sequencing the most informed candidate rests on estimated streams and gets no such prior.
PREFER_INFORMED = {"full": 1.5, "partial": 1.5, "none": 1.0}


def _pick(recs: list[Reconstruction], sequencing: str) -> Reconstruction:
    """The candidate with the smallest expected error, the less informed ones' taken ``PREFER_INFORMED`` times."""
    top = max(INFORMED.get(r.method, 0) for r in recs)
    factor = PREFER_INFORMED.get(sequencing, 1.0)

    def score(r: Reconstruction) -> float:
        e = float(r.info["quality"]["expected_error_mm"])
        return e * factor if INFORMED.get(r.method, 0) < top else e

    return min(recs, key=score)


def candidates(
    obs: Observations,
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None = None,
    frame_times_s: np.ndarray | None = None,
) -> Iterator[tuple[str, dict[str, Any]]]:
    """The methods ``auto`` tries on ``obs``, in the order it tries them, with their options.

    A generator: the order-free candidates are only looked up (which loads the GTT-Net module, and torch)
    when ``auto`` gets that far, so a decisive classical first candidate never loads torch.

    Args:
        obs: Observations of any sequencing condition.
        fps: Nominal per-camera rates for clock recovery.
        frame_times_s: Per-image times on each camera's clock, for clock recovery.

    Yields:
        ``(method, options)`` in the order ``auto`` runs them: the most informed (on matching input the most
        accurate) first, except without sequencing, where the cheap learned model runs before
        ``stream-sync`` (both always run, to check each other).
    """
    clocks = {"fps": fps, "frame_times_s": frame_times_s}
    if obs.sequencing == "full":
        yield "hpf", {"spacing": "time"}
        yield "sync", clocks
    elif obs.sequencing == "partial":
        yield "sync", clocks
    from gttnet.sync.method import order_free_fallback

    learned = order_free_fallback(obs) == "gttnet"
    if obs.sequencing == "none":
        if learned:
            yield "gttnet", {}
        yield "stream-sync", {"fps": fps, "fallback": None}
        yield "dloe", {}
        yield "pseudo", {}
        return
    if learned:
        yield "gttnet", {}
    yield "dloe", {}


def _hidden_mm(quality: Mapping[str, Any], *, timed: bool = False) -> float:
    """The part of ``expected_error_mm`` the medians cannot see and another candidate might do better on, mm.

    Images the other cameras contradict always count; weakly observed points only where the candidate
    recovered the timing and no camera was left out: with given timestamps, or with a blind camera left
    out, they are the capture's own (one camera at a time) and no other candidate places them better,
    while recovered clocks that pulled the cameras apart (a wrong declared rate) leave them too.
    """
    from gttnet.quality import CALIBRATION

    out = float(quality.get("outlier_fraction") or 0.0) * float(quality.get("outlier_mm") or 0.0)
    hidden = float(CALIBRATION.get("outlier_factor", 1.0)) * out
    if not timed and not (quality.get("blind_fraction") or 0.0):
        hidden += float(quality.get("weak_fraction") or 0.0) * float(quality.get("weak_mm") or 0.0)
    return hidden


def decisive(quality: Mapping[str, Any], *, timed: bool = False) -> bool:
    """Whether a candidate's self-assessment leaves nothing to gain from trying the others.

    Its residual is within :data:`STOP_EXCESS` of the capture's measured noise, its held-out error
    within :data:`STOP_HOLDOUT` of the noise at the joints' depth (thresholds relative to the capture's
    own noise, never fixed pixels), and every image without observations (a blind camera) is either left
    without a pose (a camera no clock could be recovered for, reported as left out: ``blind_mm`` 0) or
    placed by its timestamp (``timed``: the candidate solves on the given timestamps). No other candidate
    has evidence to place such images better: the less informed ones can only guess where in the motion
    they belong. And what the medians cannot see (:func:`_hidden_mm`: contradicted images, weak points under
    recovered clocks) makes at most :data:`STOP_HIDDEN` of its expected error.
    """
    if quality.get("sigma_px") is None:
        return False
    if (
        (quality.get("blind_fraction") or 0.0) > 0.0
        and not timed
        and float(quality.get("blind_mm") or 0.0) > 0.0
    ):
        return False
    if _hidden_mm(quality, timed=timed) > STOP_HIDDEN * float(quality.get("expected_error_mm") or 0.0):
        return False
    ex, hold = quality.get("excess"), quality.get("holdout_ratio")
    if ex is None or hold is None:
        return False
    return float(ex) <= STOP_EXCESS and float(hold) <= STOP_HOLDOUT


#: Candidates not run once one of the listed ones has (nor kept when already made): DLOE is GTT-Net's solve
#: on a hand-made instead of a learned affinity, and the pseudo-triangulation is where both start. On the
#: ``val`` half of the out-of-distribution cells (``benchmarks/bench_auto.py --split val``) DLOE never beat
#: GTT-Net without sequencing or with each camera's frame order, and the pseudo-triangulation beat neither,
#: while DLOE took up to 12 s (5 px walks with missing joints) against GTT-Net's 0.5; a DLOE that
#: ``stream-sync`` made for its camera streams, a candidate at no cost, was picked once (16.2 mm where
#: GTT-Net gave 13.6). They still run where GTT-Net cannot (no bundled model for the skeleton, or an error).
SUBSUMED_BY = {"dloe": ("gttnet",), "pseudo": ("gttnet", "dloe")}
#: Candidates that solve on the given timestamps (every other one recovers or ignores the timing).
TIMED = ("hpf",)
#: Candidates whose reconstructions ``stream-sync`` uses for its camera streams (``order_recs``): made once,
#: by whichever needs them first, and reused by the other.
ORDER_METHODS = ("gttnet", "dloe", "pseudo")


def _remaining(obs: Observations, tried: Sequence[str]) -> list[str]:
    """The candidates after ``tried``, listed without loading torch: ``gttnet`` is checked only if loaded."""
    import sys

    rest = {"full": ["hpf", "sync"], "partial": ["sync"], "none": []}[obs.sequencing]
    if "gttnet.model.inference" in sys.modules:
        from gttnet.sync.method import order_free_fallback

        learned = ["gttnet"] if order_free_fallback(obs) == "gttnet" else []
    else:
        learned = ["gttnet (where a bundled model fits the skeleton)"]
    rest += learned + (["stream-sync", "dloe", "pseudo"] if obs.sequencing == "none" else ["dloe"])
    return [n for n in rest if n not in tried]


@register_method(
    "auto",
    requires="none",
    summary="try the methods the input's sequencing allows, most informed first; keep the best self-assessed",
)
def reconstruct_auto(
    obs: Observations,
    *,
    fps: float | Sequence[float] | Mapping[int, float] | None = None,
    frame_times_s: np.ndarray | None = None,
) -> Reconstruction:
    """Select among :func:`candidates` by their self-assessment (:mod:`gttnet.quality`).

    Work is shared between candidates: ``stream-sync`` takes its camera streams from the GTT-Net
    reconstruction already made and makes DLOE's only when the cheaper order sources give no right clocks;
    where GTT-Net cannot run, a DLOE (or pseudo-triangulation) it made is that candidate, not made twice.

    Args:
        obs: Observations of any sequencing condition.
        fps: Nominal per-camera rates, passed to the clock-recovering candidates.
        frame_times_s: Per-image times on each camera's clock, passed to ``sync``.

    Returns:
        The chosen candidate's reconstruction; ``info["method_ran"]`` names it and ``info["auto"]`` holds
        ``ran``, ``candidates`` (``method``, ``expected_error_mm``, ``seconds``, ``reasons``, ``reused`` for
        one another candidate made; ``error`` for one that could not run; ``skipped`` with the reason for
        one not run) and ``why``.
    """
    from gttnet.methods import reconstruct

    tried: list[dict[str, Any]] = []
    recs: list[Reconstruction] = []
    made: dict[str, Reconstruction] = {}  # order-source reconstructions, shared with stream-sync
    why = ""
    least = MIN_TRIED.get(obs.sequencing, 1)
    for name, options in candidates(obs, fps=fps, frame_times_s=frame_times_s):
        reused = name in made
        done = [t["method"] for t in tried if "expected_error_mm" in t]
        covered = [m for m in SUBSUMED_BY.get(name, ()) if m in done]
        if covered:
            reason = f"{covered[0]} ran: {name} does not improve on it"
            tried.append(
                {"method": name, "skipped": reason + (" (made for stream-sync's streams)" if reused else "")}
            )
            continue
        t0 = time.perf_counter()
        if name == "stream-sync":
            options = {**options, "order_recs": made}
        try:
            rec = made[name] if reused else reconstruct(obs, name, **options)
        except GttNetError as exc:  # e.g. a camera with too few images for clock recovery
            log.info("auto: %s cannot run (%s)", name, exc)
            tried.append({"method": name, "error": str(exc), "seconds": round(time.perf_counter() - t0, 4)})
            continue
        if name in ORDER_METHODS:
            made[name] = rec
        q = rec.info.get("quality", {})
        entry = {
            "method": name,
            "expected_error_mm": q.get("expected_error_mm"),
            "seconds": round(time.perf_counter() - t0, 4),
            "reasons": list(q.get("reasons", [])),
        }
        if reused:
            entry["reused"] = (
                f"made by stream-sync for its camera streams ({rec.seconds:.2f} s, counted there)"
            )
        tried.append(entry)
        recs.append(rec)
        if obs.sequencing == "none":  # with real timing the informed candidates are not second-guessed
            rows = [t for t in tried if "error" not in t and "skipped" not in t]
            recs = _common_noise(obs, recs, rows)
            recs = _clock_excess(recs, rows)
            recs = _agreement(recs, rows)
        best = _pick(recs, obs.sequencing)
        timed = obs.sequencing == "full" and best.method in TIMED
        if len(recs) >= least and decisive(best.info["quality"], timed=timed):
            bq = best.info["quality"]
            why = (
                f"residual {bq.get('residual_px')} px at the capture's noise ({bq.get('sigma_px')} px), held-out "
                f"error {bq.get('holdout_ratio')}x the noise: decisive, the rest not tried"
            )
            ran_now = best.info.get("method_ran", best.method)
            for rest in _remaining(obs, [t["method"] for t in tried]):
                tried.append({"method": rest, "skipped": f"{ran_now}'s self-assessment was decisive"})
            break
    if not recs:
        raise GttNetError(
            "auto: no candidate could reconstruct the input: "
            + "; ".join(f"{t['method']}: {t['error']}" for t in tried if "error" in t)
        )
    best = _pick(recs, obs.sequencing)
    ran = best.info.get("method_ran", best.method)
    n_run = sum(1 for t in tried if "skipped" not in t)
    pick = (
        f"{ran}: the smallest expected error ({best.info['quality']['expected_error_mm']} mm) of the "
        f"{n_run} candidates tried"
    )
    why = pick if not why else f"{pick}; {why}"
    auto = {"ran": ran, "candidates": tried, "why": why}
    return replace(best, info={**best.info, "method_ran": ran, "auto": auto})
