"""Load, validate, serialise and hash ``gttdata generate`` recipes (YAML <-> typed dataclasses)."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar, overload

from gttdata.errors import RecipeError
from gttdata.recipe._parse import (
    apply_overrides,
    build_dataclass,
    read_yaml_mapping,
    resolve_paths,
    to_plain,
)
from gttdata.recipe.param import PARAM_KINDS, Param
from gttdata.recipe.schema import (
    MAX_IMAGES_PER_SAMPLE,
    AugmentSpec,
    CaptureSpec,
    FileRigSpec,
    FileSource,
    GenerateRecipe,
    MotionAugmentSpec,
    ProceduralSource,
    RingRigSpec,
    SceneSpec,
    ShardSpec,
    SplitSpec,
)

R = TypeVar("R")

__all__ = [
    "apply_overrides",
    "build_dataclass",
    "AugmentSpec",
    "CaptureSpec",
    "FileRigSpec",
    "FileSource",
    "GenerateRecipe",
    "MotionAugmentSpec",
    "PARAM_KINDS",
    "Param",
    "ProceduralSource",
    "RingRigSpec",
    "SceneSpec",
    "ShardSpec",
    "SplitSpec",
    "load_recipe",
    "parse_recipe",
    "recipe_hash",
    "recipe_to_dict",
]


def _check_splits(recipe: GenerateRecipe, source: str) -> None:
    """Split names are unique and no motion (procedural seed or file path) is in two splits."""
    seen_names: set[str] = set()
    seeds: list[tuple[int, int, str, str, str]] = []
    files: dict[str, str] = {}
    for s, split in enumerate(recipe.splits):
        if split.name in seen_names:
            raise RecipeError(
                f"{source}: splits[{s}].name: expected a unique split name, found {split.name!r} twice"
            )
        seen_names.add(split.name)
        for k, src in enumerate(split.sources):
            key = f"splits[{s}].sources[{k}]"
            if isinstance(src, ProceduralSource):
                lo, hi = src.seed, src.seed + src.count - 1
                gen = _generator(src.skeleton)
                for a, b, other, okey, ogen in seeds:
                    if other != split.name and ogen == gen and lo <= b and a <= hi:
                        raise RecipeError(
                            f"{source}: {key}.seed: expected procedural seeds disjoint from split {other!r} "
                            f"({okey}: seeds {a}..{b}), found seeds {lo}..{hi}"
                        )
                seeds.append((lo, hi, split.name, key, gen))
            else:
                for p in src.paths:
                    norm = str(Path(p))
                    if files.get(norm, split.name) != split.name:
                        raise RecipeError(
                            f"{source}: {key}.paths: expected motion files disjoint across splits, found {p!r} "
                            f"in splits {files[norm]!r} and {split.name!r}"
                        )
                    files[norm] = split.name


def _generator(skeleton: str) -> str:
    """Which procedural generator makes a topology's motions (human keypoint sets share the human one)."""
    from gttdata.skeletons import skeleton_family

    return skeleton_family(skeleton) or skeleton


def _check_skeletons(recipe: GenerateRecipe, source: str) -> None:
    """Source topologies are registered and fit the source; one sample never mixes two topologies."""
    from gttdata.skeletons import available_skeletons, derivable_from_cmu31, get_skeleton

    ev = recipe.scene.n_events
    multi = recipe.scene.n_subjects > 1 or ev.kind != "value" or ev.args[0] > 1
    for s, split in enumerate(recipe.splits):
        names = set()
        for k, src in enumerate(split.sources):
            key = f"splits[{s}].sources[{k}].skeleton"
            if isinstance(src, FileSource) and src.skeleton == "native":
                names.add("native")
                continue
            try:
                name = get_skeleton(src.skeleton).name
            except KeyError:
                expected = (
                    ("'native' or " if isinstance(src, FileSource) else "")
                    + "one of "
                    + ", ".join(available_skeletons())
                )
                raise RecipeError(f"{source}: {key}: expected {expected}, found {src.skeleton!r}") from None
            if isinstance(src, FileSource) and name not in derivable_from_cmu31():
                raise RecipeError(
                    f"{source}: {key}: expected 'native' or a topology derived from CMU-31 files "
                    f"({', '.join(derivable_from_cmu31())}), found {src.skeleton!r}"
                )
            names.add(name)
        if multi and len(names) > 1:
            raise RecipeError(
                f"{source}: splits[{s}].sources: expected one skeleton per split when scene.n_events or "
                f"scene.n_subjects > 1 (a sample holds one topology), found {', '.join(sorted(names))}"
            )


def _check_registered(recipe: GenerateRecipe, source: str) -> None:
    """Augmentation names and parameters are registered; procedural kinds exist (when that module is present)."""
    from gttdata.augment import validate_augmentation

    for i, aug in enumerate(recipe.augmentations):
        problem = validate_augmentation(aug.name, aug.params, level="capture")
        if problem:
            raise RecipeError(f"{source}: augmentations[{i}].{problem}")
    _check_skeletons(recipe, source)
    try:
        from gttdata.mocap.procedural import kinds_for_skeleton
    except ImportError:  # the procedural module is optional at validation time
        return
    for s, split in enumerate(recipe.splits):
        for k, src in enumerate(split.sources):
            if not isinstance(src, ProceduralSource):
                continue
            allowed = kinds_for_skeleton(src.skeleton)
            if not allowed:
                raise RecipeError(
                    f"{source}: splits[{s}].sources[{k}].skeleton: expected a topology with procedural "
                    f"motions, found {src.skeleton!r} (it has none)"
                )
            for kind in src.kinds:
                if kind not in allowed:
                    raise RecipeError(
                        f"{source}: splits[{s}].sources[{k}].kinds: expected kinds among "
                        f"{', '.join(allowed)} (skeleton {src.skeleton!r}), found {kind!r}"
                    )


def _largest(p: Param) -> float:
    """The largest value a parameter draws (a normal: mean + 4 sigma, clipped to its range)."""
    if p.kind == "normal":
        top = p.args[0] + 4 * p.args[1]
        return min(top, p.hi) if p.hi is not None else top
    return max(p.args)


def _check_size(recipe: GenerateRecipe, source: str) -> None:
    """One capture holds at most MAX_IMAGES_PER_SAMPLE images (cameras x frame rate x window)."""
    cams = _largest(recipe.rig.n_cameras) if isinstance(recipe.rig, RingRigSpec) else None
    if cams is None:
        return  # a rig file: its camera count is checked when it is read
    cap = recipe.capture
    n = cams * _largest(cap.fps_hz) * _largest(cap.window_s)
    if n > MAX_IMAGES_PER_SAMPLE:
        raise RecipeError(
            f"{source}: capture: expected at most {MAX_IMAGES_PER_SAMPLE} images per sample "
            f"(rig.n_cameras x capture.fps_hz x capture.window_s), found up to {n:.3g}; "
            "lower the frame rate or the window"
        )


def parse_recipe(data: dict | None, *, source: str = "<recipe>") -> GenerateRecipe:
    """Build and validate a recipe from a plain mapping (as loaded from YAML).

    Raises:
        RecipeError: One line naming ``source``, the key, the expected type or range and the value found.
    """
    recipe = build_dataclass(GenerateRecipe, data, "", source)
    _check_splits(recipe, source)
    _check_registered(recipe, source)
    _check_size(recipe, source)
    return recipe


@overload
def load_recipe(path: str | Path, overrides: Sequence[str] = ...) -> GenerateRecipe: ...
@overload
def load_recipe(path: str | Path, overrides: Sequence[str] = ..., *, cls: type[R]) -> R: ...
def load_recipe(path: str | Path, overrides: Sequence[str] = (), *, cls: type[Any] = GenerateRecipe) -> Any:
    """Read a YAML recipe of any kind, apply ``key.sub=value`` overrides, and validate it before any work.

    The one loader of gtt recipes: ``gttdata generate`` recipes (the default), training recipes
    (``cls=gttnet.train.recipe.TrainRecipe``) and evaluation recipes (``cls=EvalRecipe``). Relative
    paths of the files a recipe reads (fields marked ``path``) resolve against the recipe file's folder;
    paths given in ``overrides`` stay relative to the working directory, as typed in a shell.

    Args:
        path: The YAML file.
        overrides: Strings like ``capture.sigma_px=4`` or ``splits.train.n_samples=10``; each value is
            parsed as a YAML scalar (or flow collection, e.g. ``capture.fps_hz=[30,15]``).
        cls: The recipe class; it provides ``from_mapping(data, overrides, source)``.

    Returns:
        The validated recipe (frozen).

    Raises:
        RecipeError: e.g. ``recipe.yaml: capture.sigma_px: expected a number >= 0 or a distribution, found 'abc'``.
    """
    error = getattr(cls, "recipe_error", RecipeError)
    data = resolve_paths(cls, read_yaml_mapping(path, error=error), Path(path).resolve().parent)
    return cls.from_mapping(data, overrides, str(path))


def recipe_to_dict(recipe: GenerateRecipe) -> dict:
    """The full recipe (defaults included) as plain data; ``parse_recipe`` of it gives back an equal recipe."""
    plain = to_plain(recipe)
    assert isinstance(plain, dict)  # a dataclass becomes a mapping
    return plain


def recipe_hash(recipe: GenerateRecipe) -> str:
    """SHA-256 hex digest of the canonical JSON of :func:`recipe_to_dict` (sorted keys, no spaces)."""
    text = json.dumps(recipe_to_dict(recipe), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()
