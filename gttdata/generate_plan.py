"""Deterministic construction of sample ``i`` of a split from a recipe, independent of any other sample."""

from __future__ import annotations

import functools
import glob
import logging
import os
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gttdata.augment import (
    bone_scale,
    decorrelate,
    get_augmentation,
    joint_subset,
    marker_offsets,
    merge_joints,
    mirror,
)
from gttdata.cameras import CameraRig, ring_rig
from gttdata.capture.sample import CaptureSample
from gttdata.capture.simulate import CaptureParams, merge_subjects, simulate_capture, simulate_events
from gttdata.errors import RecipeError
from gttdata.mocap.motion import Motion
from gttdata.recipe import FileSource, GenerateRecipe, ProceduralSource, RingRigSpec, SplitSpec

__all__ = [
    "MotionRef",
    "build_sample",
    "list_motions",
    "n_samples",
    "sample_key",
    "split_id",
    "validate_inputs",
]

_log = logging.getLogger(__name__)

#: Prefix of recipe paths that live in the motion cache of ``gttdata motions fetch``.
CACHE_PREFIX = "cache:"


@dataclass(frozen=True)
class MotionRef:
    """One motion a split may draw from.

    Args:
        name: Motion name (``procedural/<kind>/<seed>`` or the file stem); unique across splits.
        source: Index of the source in the split.
        kind: Procedural kind, or the loader format for a file.
        seed: Procedural seed (-1 for files).
        path: Resolved file path (``""`` for procedural motions).
    """

    name: str
    source: int
    kind: str
    seed: int = -1
    path: str = ""


def split_id(split: str) -> int:
    """Stable integer id of a split name (CRC-32), so split order in the recipe does not matter."""
    return zlib.crc32(split.encode())


def n_samples(recipe: GenerateRecipe) -> dict[str, int]:
    """Number of samples per split, in recipe order."""
    return {s.name: s.n_samples for s in recipe.splits}


def sample_key(recipe: GenerateRecipe, split: str, index: int) -> str:
    """Name of sample ``index`` of ``split``, e.g. ``"train/000017"`` (also ``CaptureSample.name``)."""
    _split(recipe, split)
    return f"{split}/{index:06d}"


def _split(recipe: GenerateRecipe, split: str) -> SplitSpec:
    for s in recipe.splits:
        if s.name == split:
            return s
    raise RecipeError(f"split: expected one of {', '.join(s.name for s in recipe.splits)}, found {split!r}")


def _resolve(pattern: str) -> str:
    if pattern.startswith(CACHE_PREFIX):
        from gttdata.mocap.fetch import cache_dir

        return str(cache_dir() / pattern[len(CACHE_PREFIX) :].lstrip("/"))
    return os.path.expanduser(os.path.expandvars(pattern))


@functools.lru_cache(maxsize=256)
def _expand(pattern: str) -> tuple[str, ...]:
    resolved = _resolve(pattern)
    hits = (
        sorted(glob.glob(resolved))
        if glob.has_magic(resolved)
        else [resolved]
        if Path(resolved).is_file()
        else []
    )
    if not hits:
        hint = " (run `gttdata motions fetch` first)" if pattern.startswith(CACHE_PREFIX) else ""
        raise RecipeError(
            f"expected existing motion files, found no file for {pattern!r} -> {resolved}{hint}"
        )
    from gttdata.errors import GttDataError
    from gttdata.mocap.fetch import check_cached

    for hit in hits:  # a cached file with a published checksum is used only when it matches it
        try:
            check_cached(hit)
        except GttDataError as exc:
            raise RecipeError(str(exc)) from None
    return tuple(hits)


def list_motions(recipe: GenerateRecipe, split: str) -> tuple[MotionRef, ...]:
    """Every motion of a split, in source order (file globs expanded, sorted)."""
    refs: list[MotionRef] = []
    for k, src in enumerate(_split(recipe, split).sources):
        if isinstance(src, ProceduralSource):
            kinds = src.kinds or _procedural_kinds(src.skeleton)
            # CMU-31 motions keep their historical names; other topologies name theirs.
            prefix = "procedural" if src.skeleton == "cmu31" else f"procedural/{src.skeleton}"
            for m in range(src.count):
                kind, seed = kinds[m % len(kinds)], src.seed + m
                refs.append(MotionRef(f"{prefix}/{kind}/{seed:06d}", k, kind, seed))
        else:
            for pattern in src.paths:
                try:
                    hits = _expand(pattern)
                except RecipeError as exc:
                    raise RecipeError(f"splits.{split}.sources[{k}].paths: {exc}") from exc
                refs.extend(MotionRef(Path(p).stem, k, src.format, -1, p) for p in hits)
    return tuple(refs)


def validate_inputs(recipe: GenerateRecipe) -> dict[str, int]:
    """Check, before any work, that every file source resolves and that no file is in two splits.

    Returns:
        Number of distinct motions per split.

    Raises:
        RecipeError: Naming the split and the offending pattern or file.
    """
    owner: dict[str, str] = {}
    counts = {}
    for split in recipe.splits:
        refs = list_motions(recipe, split.name)
        for r in refs:
            if r.path and owner.setdefault(os.path.realpath(r.path), split.name) != split.name:
                raise RecipeError(
                    f"splits.{split.name}.sources: expected motions disjoint across splits, found {r.path} "
                    f"also in split {owner[os.path.realpath(r.path)]!r}"
                )
        counts[split.name] = len(refs)
    return counts


def _procedural_kinds(skeleton: str = "cmu31") -> tuple[str, ...]:
    from gttdata.mocap.procedural import kinds_for_skeleton

    return tuple(kinds_for_skeleton(skeleton))


@functools.lru_cache(maxsize=32)
def _procedural_motion(
    kind: str, seed: int, duration_s: float, fps_hz: float, skeleton: str = "cmu31"
) -> Motion:
    from gttdata.mocap.procedural import generate_skeleton_motion

    return generate_skeleton_motion(skeleton, kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)


@functools.lru_cache(maxsize=64)
def _file_motion(path: str, fmt: str, skeleton: str = "native") -> Motion:
    from gttdata.mocap import load_motion

    motion = load_motion(path, fmt=fmt)
    if skeleton == "native":
        return motion
    from gttdata.skeletons import derive_from_cmu31

    try:
        return derive_from_cmu31(motion, skeleton)
    except ValueError as exc:
        raise RecipeError(f"{path}: skeleton {skeleton!r}: {exc}") from None


@functools.lru_cache(maxsize=8)
def _file_rig(path: str) -> CameraRig:
    return CameraRig.load(_resolve(path))


def _load(ref: MotionRef, src: ProceduralSource | FileSource) -> Motion:
    """The full (trimmed) motion of a reference; cached per process."""
    if isinstance(src, ProceduralSource):
        # The duration is a property of the motion, so it is drawn from the motion's own seed.
        dur = float(src.duration_s.draw(np.random.default_rng([src.seed, ref.seed, 0x6D6F74])))
        motion = _procedural_motion(ref.kind, ref.seed, dur, src.fps_hz, src.skeleton)
    else:
        motion = _file_motion(ref.path, src.format, src.skeleton)
    if src.trim_start_s or src.trim_end_s:
        motion = motion.trim(src.trim_start_s, motion.duration_s - src.trim_end_s)
    return motion


def _pick_refs(refs, sources, k: int, rng: np.random.Generator, first: int | None = None) -> list[MotionRef]:
    """``k`` motions, by source weight (split evenly within a source), distinct when possible.

    ``first`` (an index into ``refs``) fixes the first motion; the others are drawn without it.
    """
    per_source = np.bincount([r.source for r in refs], minlength=len(sources))
    p = np.array([sources[r.source].weight / per_source[r.source] for r in refs])
    if first is None:
        idx = rng.choice(len(refs), size=k, replace=k > len(refs), p=p / p.sum())
        return [refs[i] for i in np.atleast_1d(idx)]
    if k == 1:
        return [refs[first]]
    rest = np.delete(np.arange(len(refs)), first) if len(refs) > 1 else np.arange(len(refs))
    q = p[rest]
    idx = rng.choice(rest, size=k - 1, replace=k - 1 > len(rest), p=q / q.sum())
    return [refs[first], *(refs[i] for i in np.atleast_1d(idx))]


def _first_motion(recipe: GenerateRecipe, split: str, refs, sources, index: int) -> int | None:
    """Index into ``refs`` of sample ``index``'s first motion, covering the split's motions evenly.

    When every motion has the same weight, sample i takes motion ``order[i mod M]`` of a permutation
    seeded by (recipe seed, split) alone, so M consecutive samples use M distinct motions (a test split
    of 10 samples over 10 motions uses each once) and sample i still depends only on (seed, split, i).
    With unequal weights the first motion is drawn by weight (returns None).
    """
    per_source = np.bincount([r.source for r in refs], minlength=len(sources))
    p = np.array([sources[r.source].weight / per_source[r.source] for r in refs])
    if not np.allclose(p, p[0]):
        return None
    order = np.random.default_rng(np.random.SeedSequence([recipe.seed, split_id(split)])).permutation(
        len(refs)
    )
    return int(order[index % len(refs)])


def _recenter(motion: Motion) -> Motion:
    """Translate so the mean root position over the motion is above the world origin (z kept)."""
    shift = motion.positions[:, 0, :].mean(axis=0)
    shift[2] = 0.0
    return Motion(motion.positions - shift, motion.fps_hz, motion.skeleton, motion.name, motion.provenance)


def _build_rig(recipe: GenerateRecipe, rng: np.random.Generator) -> tuple[CameraRig, dict]:
    spec = recipe.rig
    if not isinstance(spec, RingRigSpec):
        rig = _file_rig(spec.path)
        return rig, {"kind": "file", "path": spec.path, "n_cameras": len(rig)}
    n_cameras = int(spec.n_cameras.draw(rng))
    d = {
        "radius_m": float(spec.radius_m.draw(rng)),
        "height_m": float(spec.height_m.draw(rng)),
        "f_px": float(spec.f_px.draw(rng)),
        "jitter_m": float(spec.jitter_m.draw(rng)),
        "jitter_deg": float(spec.jitter_deg.draw(rng)),
        "start_angle_deg": float(rng.uniform(0.0, 360.0)) if spec.random_azimuth else 0.0,
    }
    target = (0.0, 0.0, float(spec.target_height_m.draw(rng)))
    w, h = spec.image_size
    rig = ring_rig(n_cameras, target=target, image_size=(int(w), int(h)), rng=rng, **d)
    return rig, {
        "kind": "ring",
        "n_cameras": n_cameras,
        **d,
        "target": list(target),
        "image_size": list(spec.image_size),
    }


def _camera_motion(ptz_prob: float, rng: np.random.Generator) -> str:
    """``"ptz"`` with probability ``ptz_prob``, else ``"fixed"``; draws nothing when the answer is certain."""
    if ptz_prob <= 0.0:
        return "fixed"
    return "ptz" if ptz_prob >= 1.0 or rng.random() < ptz_prob else "fixed"


def _capture_params(
    recipe: GenerateRecipe, n_cameras: int, window_s: float, rng: np.random.Generator
) -> CaptureParams:
    c = recipe.capture
    fps = c.fps_hz.draw(rng, size=1 if c.fps_shared else n_cameras)
    return CaptureParams(
        fps_hz=tuple(float(f) for f in np.broadcast_to(fps, (n_cameras,))),
        duration_s=window_s,
        stagger=c.stagger,
        start_spread_s=float(c.start_spread_s.draw(rng)),
        min_gap_s=c.min_gap_s,
        jitter_s=float(c.jitter_s.draw(rng)),
        drift_ppm=tuple(float(d) for d in c.drift_ppm.draw(rng, size=n_cameras)),
        sigma_px=float(c.sigma_px.draw(rng)),
        outlier_rate=float(c.outlier_rate.draw(rng)),
        outlier_sigma_px=float(c.outlier_sigma_px.draw(rng)),
        joint_drop_rate=float(c.joint_drop_rate.draw(rng)),
        image_drop_rate=float(c.image_drop_rate.draw(rng)),
        # Drawn after the older fields (constants draw nothing), so older recipes keep their samples.
        camera_motion=_camera_motion(float(c.ptz_prob.draw(rng)), rng),
        ptz_lag_s=float(c.ptz_lag_s.draw(rng)),
        ptz_aim_deg=float(c.ptz_aim_deg.draw(rng)),
        ptz_subject_px=float(c.ptz_subject_px.draw(rng)),
        noise_corr_s=float(c.noise_corr_s.draw(rng)),
        swap_rate=float(c.swap_rate.draw(rng)),
        miss_run_frames=float(c.miss_run_frames.draw(rng)),
    )


def _scene_motions(
    recipe: GenerateRecipe, split: SplitSpec, refs, rng: np.random.Generator, *, first: int | None = None
):
    """Motion windows of every event (subjects merged); also the window length and per-motion records."""
    scene = recipe.scene
    n_events = int(scene.n_events.draw(rng))
    picked = _pick_refs(refs, split.sources, n_events * scene.n_subjects, rng, first)
    full = [_load(r, split.sources[r.source]) for r in picked]
    lead = split.sources[picked[0].source]
    window = float((lead.window_s or recipe.capture.window_s).draw(rng))
    shortest = min(m.duration_s for m in full)
    if window > shortest:
        _log.warning(
            "window %.3f s is longer than motion %s (%.3f s): using %.3f s",
            window,
            picked[0].name,
            shortest,
            shortest,
        )
        window = shortest
    maug = recipe.motion_augment
    records, events = [], []
    # One topology draw per sample, shared by every event and subject (they are simulated as one).
    topo = maug.joint_subset_prob or maug.merge_prob or maug.marker_prob
    topo_seed = int(rng.integers(2**63)) if topo else None
    for e in range(n_events):
        subjects = []
        for s in range(scene.n_subjects):
            ref, motion = picked[e * scene.n_subjects + s], full[e * scene.n_subjects + s]
            start = float(rng.uniform(0.0, motion.duration_s - window))
            m = motion.trim(start, start + window + 2.0 / motion.fps_hz)
            m2 = mirror(m, rng, prob=maug.mirror_prob)
            factor = float(maug.bone_scale.draw(rng))
            m3 = decorrelate(bone_scale(m2, rng, factor=factor), rng, prob=maug.decorrelate_prob)
            subjects.append(_recenter(m3) if recipe.capture.recenter else m3)
            records.append(
                {
                    "name": ref.name,
                    "event": e,
                    "subject": s,
                    "start_s": start,
                    "mirrored": m2 is not m,
                    "bone_scale": factor,
                    "decorrelated": m3.name.endswith("+decorrelated"),
                }
            )
        subjects = _topology(subjects, maug, topo_seed)
        if len(subjects) > 1:
            heading = rng.uniform(0.0, 2 * np.pi)
            sep = float(scene.subject_separation_m.draw(rng))
            along = (np.arange(len(subjects)) - (len(subjects) - 1) / 2) * sep
            offsets = along[:, None] * np.array([np.cos(heading), np.sin(heading), 0.0])
            for rec, off in zip(records[-len(subjects) :], offsets, strict=True):
                rec["offset_m"] = off.tolist()
            events.append(merge_subjects(subjects, offsets))
        else:
            events.append(subjects[0])
    return events, window, records


def _topology(motions: list[Motion], maug, seed: int | None) -> list[Motion]:
    """The recipe's topology augmentations, drawn from ``seed``: the same map for every motion given.

    ``seed`` is None when every probability is 0 (then nothing was drawn, so recipes without them
    keep their shards).
    """
    if seed is None:
        return motions
    out = []
    for m in motions:
        r = np.random.default_rng(seed)
        m = joint_subset(m, r, prob=maug.joint_subset_prob, min_keep=maug.joint_subset_min_keep)
        m = merge_joints(m, r, prob=maug.merge_prob)
        out.append(marker_offsets(m, r, prob=maug.marker_prob, max_frac=maug.marker_max_frac))
    return out


def build_sample(recipe: GenerateRecipe, split: str, index: int) -> list[CaptureSample]:
    """Build sample ``index`` of ``split``: the original capture and its stored augmented variants.

    All randomness comes from ``SeedSequence([recipe.seed, split_id(split), index])``, so a sample
    can be rebuilt alone and the result does not depend on worker count or order.

    Args:
        recipe: A validated recipe.
        split: Split name.
        index: Sample index in ``[0, n_samples[split])``.

    Returns:
        ``[orig, *variants]``, one variant per ``recipe.augmentations`` entry, all with the same name.
    """
    spec = _split(recipe, split)
    if not 0 <= index < spec.n_samples:
        raise RecipeError(f"index: expected 0 <= index < {spec.n_samples} for split {split!r}, found {index}")
    ss = np.random.SeedSequence([recipe.seed, split_id(split), index])
    r_motion, r_rig, r_capture, r_sim, *r_aug = (
        np.random.default_rng(c) for c in ss.spawn(4 + len(recipe.augmentations))
    )
    refs = list_motions(recipe, split)
    first = _first_motion(recipe, split, refs, spec.sources, index)
    events, window, records = _scene_motions(recipe, spec, refs, r_motion, first=first)
    rig, rig_meta = _build_rig(recipe, r_rig)
    params = _capture_params(recipe, len(rig), window, r_capture)
    name = sample_key(recipe, split, index)
    motion_name = "|".join(dict.fromkeys(r["name"] for r in records))
    if len(events) > 1:
        gaps = np.atleast_1d(recipe.scene.event_gap_s.draw(r_capture, size=len(events) - 1)).tolist()
        sample = simulate_events(events, rig, params, r_sim, gaps_s=gaps, name=name, motion_name=motion_name)
    else:
        sample = simulate_capture(events[0], rig, params, r_sim, name=name, motion_name=motion_name)
    meta = {
        **sample.meta,
        "split": split,
        "index": index,
        "recipe_seed": recipe.seed,
        "rig": rig_meta,
        "motions": records,
        "n_events": len(events),
        "n_subjects": recipe.scene.n_subjects,
    }
    orig = sample.replace(meta=meta)
    out = [orig]
    for aug_spec, rng in zip(recipe.augmentations, r_aug, strict=True):
        aug = get_augmentation(aug_spec.name, level="capture")
        out.append(aug.fn(orig, rng, **aug_spec.params))
    return out
