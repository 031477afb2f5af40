"""Typed, frozen dataclasses that map one-to-one onto a ``gttdata generate`` YAML recipe."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from gttdata.recipe.param import Param

__all__ = [
    "AugmentSpec",
    "CaptureSpec",
    "FileRigSpec",
    "FileSource",
    "GenerateRecipe",
    "MotionAugmentSpec",
    "ProceduralSource",
    "RingRigSpec",
    "SceneSpec",
    "ShardSpec",
    "SplitSpec",
]


#: Sanity bounds (refused with one line): beyond them a recipe is almost surely a typo (``1e12``), and
#: generation would grow memory or disk for hours before failing.
MAX_SAMPLES_PER_SPLIT = 100_000_000
MAX_FPS_HZ = 10_000
MAX_WINDOW_S = 3_600.0
#: Largest number of images one capture may hold (cameras x frame rate x window).
MAX_IMAGES_PER_SAMPLE = 100_000


def _f(default, *, factory=None, **check):
    """A dataclass field whose ``metadata`` holds its validation rule (ge, gt, le, lt, choices, integer...)."""
    if factory is not None:
        return field(default_factory=factory, metadata=check)
    return field(default=default, metadata=check)


def _p(value, **check):
    """A :class:`Param` field with a fixed default ``value`` and its range rule."""
    lo = check.get("ge", check.get("gt"))
    hi = check.get("le", check.get("lt"))
    integer = bool(check.get("integer", False))
    return field(default=Param.of(value, integer=integer, lo=lo, hi=hi), metadata={**check, "param": True})


@dataclass(frozen=True)
class ShardSpec:
    """How samples are packed into HDF5 shards.

    Args:
        samples_per_shard: Roll over to a new shard after this many samples.
        max_bytes: Roll over before a shard would exceed this many bytes.
        compression: HDF5 filter for the arrays: ``none``, ``gzip`` or ``lzf``.
    """

    samples_per_shard: int = _f(256, ge=1)
    max_bytes: int = _f(1 << 30, ge=1)
    compression: str = _f("gzip", choices=("none", "gzip", "lzf"))


@dataclass(frozen=True)
class ProceduralSource:
    """Motions synthesised by :mod:`gttdata.mocap.procedural`.

    Motion ``m`` (``0 <= m < count``) has seed ``seed + m`` and kind ``kinds[m % len(kinds)]``; two
    splits must use disjoint seed ranges, so no motion appears in two splits.

    Args:
        kind: Always ``procedural``.
        kinds: Procedural motion kinds to cycle through (empty: all ``PROCEDURAL_KINDS``).
        count: Number of distinct motions in this source.
        seed: Seed of motion 0.
        duration_s: Length of each generated motion, seconds (drawn once per motion).
        fps_hz: Sampling rate of the generated motion.
        trim_start_s: Seconds cut from the start of each motion before windows are chosen.
        trim_end_s: Seconds cut from the end.
        window_s: Capture window length for this source (None: ``capture.window_s``).
        weight: Relative probability of drawing a sample's motion from this source.
        skeleton: Registered topology of the motions (:mod:`gttdata.skeletons`): ``cmu31`` and the
            human keypoint sets derived from it take the human kinds, ``hand21`` the hand kinds
            (grasp, spread, point, wave), ``quadruped36`` the quadruped kinds (walk, trot, turn, sit).
    """

    kind: str = _f("procedural", choices=("procedural",))
    kinds: tuple[str, ...] = ()
    count: int = _f(16, ge=1)
    seed: int = _f(0, ge=0)
    duration_s: Param = _p(6.0, gt=0)
    fps_hz: float = _f(120.0, gt=0, le=MAX_FPS_HZ)
    trim_start_s: float = _f(0.0, ge=0)
    trim_end_s: float = _f(0.0, ge=0)
    window_s: Param | None = _f(None, gt=0, param=True)
    weight: float = _f(1.0, gt=0)
    skeleton: str = _f("cmu31", omit_default=True)


@dataclass(frozen=True)
class FileSource:
    """Motions read from files with :func:`gttdata.mocap.load_motion`.

    Paths may be globs; ``cache:`` as a prefix means the motion cache of ``gttdata motions fetch``, and
    ``$VARS`` are expanded; other relative paths in a recipe file are relative to that file's folder
    (:func:`gttdata.recipe.load_recipe`), those given as overrides to the working directory.

    Args:
        kind: Always ``files``.
        paths: Files or glob patterns (sorted after expansion).
        format: Loader name for ``load_motion`` (``auto``: by suffix).
        trim_start_s: Seconds cut from the start of each motion (e.g. a T-pose).
        trim_end_s: Seconds cut from the end.
        window_s: Capture window length for this source (None: ``capture.window_s``).
        weight: Relative probability of drawing a sample's motion from this source.
        skeleton: ``native`` keeps each file's own joints (e.g. a C3D clip's markers, as they are);
            a human keypoint-set name (``coco17``...) derives it from CMU-31 files.
    """

    kind: str = _f("files", choices=("files",))
    paths: tuple[str, ...] = _f((), nonempty=True, path=True)
    format: str = "auto"
    trim_start_s: float = _f(0.0, ge=0)
    trim_end_s: float = _f(0.0, ge=0)
    window_s: Param | None = _f(None, gt=0, param=True)
    weight: float = _f(1.0, gt=0)
    skeleton: str = _f("native", omit_default=True)


#: Split and dataset names: they become folder and file names, so never ``.``, ``..``, a hidden name, a
#: path (``/``) or empty. ``\Z``, not ``$``: a trailing newline is refused too.
NAME_PATTERN = r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*\Z"


@dataclass(frozen=True)
class SplitSpec:
    """One dataset split; splits never share a motion.

    Args:
        name: Split name (``train``, ``val``, ``test``...).
        n_samples: Number of captures in the split.
        sources: Where the split's motions come from.
    """

    name: str = _f("train", pattern=NAME_PATTERN)
    n_samples: int = _f(1, ge=0, le=MAX_SAMPLES_PER_SPLIT)
    sources: tuple[ProceduralSource | FileSource, ...] = _f((), nonempty=True)


@dataclass(frozen=True)
class RingRigSpec:
    """A ring of cameras around the subject (see :func:`gttdata.cameras.ring_rig`), drawn per sample.

    Args:
        kind: Always ``ring``.
        n_cameras: Number of cameras V.
        radius_m: Horizontal camera distance from the subject, metres.
        height_m: Camera height above the floor, metres.
        target_height_m: Height of the aim point above the floor, metres.
        f_px: Focal length, pixels.
        image_size: ``[width, height]`` in pixels.
        jitter_m: Std of the Gaussian perturbation of each camera centre, metres.
        jitter_deg: Std of the Gaussian perturbation of each camera azimuth, degrees.
        random_azimuth: Rotate the whole ring by a uniform random azimuth.
    """

    kind: str = _f("ring", choices=("ring",))
    n_cameras: Param = _p(4, ge=2, le=64, integer=True)  # one camera cannot triangulate
    radius_m: Param = _p(3.0, gt=0)
    height_m: Param = _p(1.0)
    target_height_m: Param = _p(0.9)
    f_px: Param = _p(1000.0, gt=0)
    image_size: tuple[int, int] = _f((1000, 1000), ge=1)
    jitter_m: Param = _p(0.0, ge=0)
    jitter_deg: Param = _p(0.0, ge=0)
    random_azimuth: bool = True


@dataclass(frozen=True)
class FileRigSpec:
    """A fixed rig read from a TOML/JSON rig file; the subject is centred on the world origin.

    Args:
        kind: Always ``file``.
        path: Rig file (``.toml`` aniposelib layout or ``.json``); relative to the recipe file's folder.
    """

    kind: str = _f("file", choices=("file",))
    path: str = _f("", nonempty=True, path=True)


@dataclass(frozen=True)
class CaptureSpec:
    """How each capture is recorded.

    How each capture is recorded. Each parameter is a value or a distribution drawn per sample;
    ``fps_hz`` and ``drift_ppm`` are drawn per camera.

    Args:
        window_s: Capture duration, seconds.
        fps_hz: Frame rate per camera, Hz; a list gives camera v the rate ``list[v % len]``.
        fps_shared: Draw one rate for all cameras instead of one per camera.
        stagger: Camera clock offsets: ``even`` (camera slot v at ``v / (V fps_max)``, slots shuffled) or
            ``random`` (uniform in one period); both are then checked so no two images are concurrent.
        start_spread_s: Cameras started by hand: each camera's first frame is delayed by a further
            ``uniform(0, start_spread_s)`` seconds (drawn per camera); it records until the window ends.
        min_gap_s: Smallest allowed time between any two images of different cameras, seconds.
        jitter_s: Std of the per-image timing jitter, seconds (clipped to a quarter period).
        drift_ppm: Clock rate error of each camera, parts per million.
        sigma_px: Std of the Gaussian 2-D detection noise, pixels.
        outlier_rate: Fraction of observed joints replaced by outliers.
        outlier_sigma_px: Std of the outliers' displacement, pixels.
        joint_drop_rate: Fraction of joints dropped at random (on top of out-of-image / behind-camera).
        image_drop_rate: Fraction of whole images dropped.
        recenter: Translate the motion window so its mean root position is above the world origin.
        ptz_prob: Probability that a sample's cameras are pan-tilt-zoom cameras: each stays in place but
            pans and tilts after the subject, one pose per image, as in broadcast footage
            (:func:`gttdata.capture.realism.pan_tilt_zoom_poses`); otherwise they are fixed.
        ptz_lag_s: Operator lag of a ``ptz`` camera, seconds.
        ptz_aim_deg: Std of a ``ptz`` camera's drifting aiming error, degrees.
        ptz_subject_px: Zoom of a ``ptz`` camera: the subject's height in pixels (0: fixed focal length).
        noise_corr_s: Correlation time of the detection noise along each camera's stream, seconds (0:
            independent per image).
        swap_rate: Probability per image that a detector swaps every left/right joint pair.
        miss_run_frames: Mean length, in frames, of the runs in which a joint is missed (0 or 1: joints
            are dropped independently); the fraction missed stays ``joint_drop_rate``.
    """

    window_s: Param = _p(2.5, gt=0, le=MAX_WINDOW_S)
    fps_hz: Param = _p(30.0, gt=0, le=MAX_FPS_HZ, allow_list=True)
    fps_shared: bool = False
    stagger: str = _f("even", choices=("even", "random"))
    start_spread_s: Param = _p(0.0, ge=0)
    min_gap_s: float = _f(1e-4, gt=0)
    jitter_s: Param = _p(0.0, ge=0)
    drift_ppm: Param = _p(0.0)
    sigma_px: Param = _p(2.0, ge=0)
    outlier_rate: Param = _p(0.0, ge=0, le=1)
    outlier_sigma_px: Param = _p(50.0, ge=0)
    joint_drop_rate: Param = _p(0.0, ge=0, lt=1)  # 1 would leave nothing to reconstruct
    image_drop_rate: Param = _p(0.0, ge=0, lt=1)
    recenter: bool = True
    # Off at their defaults and left out of the recipe's hash there, so older recipes keep their hash.
    ptz_prob: Param = _p(0.0, ge=0, le=1, omit_default=True)
    ptz_lag_s: Param = _p(0.3, ge=0, le=10, omit_default=True)
    ptz_aim_deg: Param = _p(1.0, ge=0, le=30, omit_default=True)
    ptz_subject_px: Param = _p(0.0, ge=0, le=10000, omit_default=True)
    noise_corr_s: Param = _p(0.0, ge=0, le=60, omit_default=True)
    swap_rate: Param = _p(0.0, ge=0, le=1, omit_default=True)
    miss_run_frames: Param = _p(0.0, ge=0, le=10000, omit_default=True)


@dataclass(frozen=True)
class SceneSpec:
    """What the cameras see: several disjoint events in time, and/or several subjects at once.

    Args:
        n_events: Number of temporally disjoint events (each a different motion window).
        event_gap_s: Gap between consecutive events, seconds (no images are taken in a gap).
        n_subjects: Subjects per image; > 1 gives a skeleton of ``n_subjects x J`` joints whose names
            carry the prefixes ``a_``, ``b_``, ... (see :func:`gttdata.capture.simulate.merge_subjects`).
        subject_separation_m: Horizontal distance between neighbouring subjects' mean root positions, metres.
    """

    n_events: Param = _p(1, ge=1, le=16, integer=True)
    event_gap_s: Param = _p(1.0, gt=0)
    n_subjects: int = _f(1, ge=1, le=8)
    subject_separation_m: Param = _p(1.5, ge=0)


@dataclass(frozen=True)
class MotionAugmentSpec:
    """Edits applied to each motion before simulation (registry level ``motion``).

    Args:
        mirror_prob: Probability of a left/right mirror.
        bone_scale: Factor applied to every bone length.
        decorrelate_prob: Probability of the "decorrelated motion" control: an independent random rigid
            motion per joint trajectory (:func:`gttdata.augment.decorrelate`).
        joint_subset_prob: Probability of keeping a random subset of the joints
            (:func:`gttdata.augment.joint_subset`), so that samples need not share a topology.
        joint_subset_min_keep: Smallest fraction of joints a subset keeps.
        merge_prob: Probability of merging random joints into their parents
            (:func:`gttdata.augment.merge_joints`).
        marker_prob: Probability of replacing joints by markers offset along their bones
            (:func:`gttdata.augment.marker_offsets`).
        marker_max_frac: Largest marker offset, as a fraction of the adjacent bone's length.
    """

    mirror_prob: float = _f(0.0, ge=0, le=1)
    bone_scale: Param = _p(1.0, gt=0)
    decorrelate_prob: float = _f(0.0, ge=0, le=1)
    joint_subset_prob: float = _f(0.0, ge=0, le=1, omit_default=True)
    joint_subset_min_keep: float = _f(0.5, gt=0, le=1, omit_default=True)
    merge_prob: float = _f(0.0, ge=0, le=1, omit_default=True)
    marker_prob: float = _f(0.0, ge=0, le=1, omit_default=True)
    marker_max_frac: float = _f(0.25, ge=0, le=0.5, omit_default=True)


@dataclass(frozen=True)
class AugmentSpec:
    """One stored capture-level variant: a registered augmentation and its parameters.

    Args:
        name: Registered name (see :func:`gttdata.augment.available_augmentations`).
        params: Keyword arguments of the augmentation.
    """

    name: str = ""
    params: dict = _f(None, factory=dict)


@dataclass(frozen=True)
class GenerateRecipe:
    """A ``gttdata generate`` recipe.

    Args:
        name: Dataset name.
        seed: Root seed; sample ``i`` of split ``s`` draws from ``SeedSequence([seed, crc32(s), i])``.
        output_dir: Where shards and the manifest go.
        shard: Shard packing.
        splits: The splits (at least one), disjoint in motions.
        rig: Camera rig (``ring`` or ``file``).
        capture: Capture timing, noise and missing data.
        scene: Events and subjects.
        motion_augment: Motion edits before simulation.
        augmentations: Capture-level variants stored next to each original sample.
    """

    name: str = _f("gttdata", pattern=NAME_PATTERN)
    seed: int = _f(0, ge=0)
    output_dir: str = "data/gttdata"
    shard: ShardSpec = _f(None, factory=ShardSpec)
    splits: tuple[SplitSpec, ...] = _f((), nonempty=True)
    rig: RingRigSpec | FileRigSpec = _f(None, factory=RingRigSpec)
    capture: CaptureSpec = _f(None, factory=CaptureSpec)
    scene: SceneSpec = _f(None, factory=SceneSpec)
    motion_augment: MotionAugmentSpec = _f(None, factory=MotionAugmentSpec)
    augmentations: tuple[AugmentSpec, ...] = ()

    @classmethod
    def from_mapping(cls, data: dict, overrides: Sequence[str] = (), source: str = "") -> GenerateRecipe:
        """Apply ``key.sub=value`` overrides to a raw mapping, then build and validate the recipe."""
        from gttdata.recipe import parse_recipe
        from gttdata.recipe._parse import apply_overrides

        return parse_recipe(
            apply_overrides(data, overrides, source or "<recipe>"), source=source or "<recipe>"
        )
