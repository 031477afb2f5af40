"""TrainRecipe: the typed form of a ``recipes/gttnet/*.yaml`` file, with ``key.sub=value`` overrides."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from gttdata.errors import RecipeError
from gttdata.recipe import apply_overrides, build_dataclass, load_recipe
from gttnet.train.stages import Stage

__all__ = [
    "RecipeError",
    "ModelSpec",
    "DataSpec",
    "TrainSpec",
    "TrainRecipe",
    "load_train_recipe",
    "parse_train_recipe",
    "recipe_to_dict",
    "run_folder",
    "saved_run_recipe",
]


#: Ranges of the loop settings (refused with one line beyond them, like every recipe range): larger values
#: are typos that would exhaust memory or processes.
MAX_BATCH_SIZE = 4096
MAX_WORKERS = 256


@dataclass(frozen=True)
class ModelSpec:
    """Which network to build.

    Args:
        builder: Registered builder name (``gttnet_tiny``, ``gttnet_base``, ``gttnet_pointnet``).
        settings: :class:`~gttnet.model.network.GTTNetConfig` fields overriding the builder's values.
        init: Start from these weights (a model file or run directory) instead of a random initialisation;
            the architecture must match.
    """

    builder: str = "gttnet_base"
    settings: dict[str, Any] = field(default_factory=dict)
    init: str | None = field(default=None, metadata={"path": True})


@dataclass(frozen=True)
class SourceSpec:
    """One source of captures: a gttdata generate recipe, built on the fly or read from its shards.

    Args:
        generate: The ``gttdata`` generate recipe describing the data (relative to the recipe file).
        overrides: ``key=value`` overrides of that recipe.
        kind: ``"recipe"``: build every sample on the fly (deterministic per index, no disk);
            ``"shards"``: read shards under ``root``, generating them first when absent.
        root: Shard directory for ``kind: shards`` (default: the generate recipe's ``output_dir``);
            a data folder, so relative to the working directory like every output folder.
        manifest: For ``kind: shards``, the registered manifest the shards must match (e.g.
            ``manifests/default.json``): the recipe hash and every shard's size and SHA-256 are checked
            before training, so a run never trains on data other than the dataset it names.
        max_train: Use at most this many of its training samples (None: all).
        max_val: Use at most this many of its validation samples (None: all).
    """

    generate: str = field(default="recipes/gttdata/tiny.yaml", metadata={"path": True})
    overrides: list[str] = field(default_factory=list)
    kind: str = "recipe"
    root: str | None = None
    manifest: str | None = field(default=None, metadata={"path": True})
    max_train: int | None = field(default=None, metadata={"ge": 1})
    max_val: int | None = field(default=4, metadata={"ge": 0})

    def __post_init__(self) -> None:
        if self.kind not in ("recipe", "shards"):
            raise ValueError(f"kind must be 'recipe' or 'shards', got {self.kind!r}")
        if self.manifest is not None and self.kind != "shards":
            raise ValueError(
                f"manifest {self.manifest!r} applies to kind 'shards' only, got kind {self.kind!r}"
            )


@dataclass(frozen=True)
class DataSpec:
    """Where training sequences come from and how each is presented.

    Args:
        sources: Capture sources; their splits are concatenated.
        train_split: Split used for training.
        val_split: Held-out split used for validation (each sample under every weighted condition).
        sequencing: Relative frequency of each sequencing condition (none / partial / full) per item.
        variants: Stored sample variants to draw from (``orig`` and augmentation names).
        num_workers: DataLoader worker processes (items are prepared in the workers).
        cache: Where prepared items (X_init, neighbourhoods, targets) are kept after first use: ``"disk"``
            (``RUN_DIR/item_cache``, shared by all workers, removed when the run finishes), ``"memory"``
            (per worker process) or ``"none"``.
        stream_order: Present order-free (``none``) sequences as inference does by default for a model
            without a PointNet front end: each camera's images ordered by the pseudo-triangulated poses and
            the capture given to the network as a ``partial`` one, its chain links weighted by pose
            similarity (:func:`gttnet.model.inputs.prepare_stream_ordered_inputs`), so a model trained for
            ``none`` sees the inputs it will be run on.
    """

    sources: list[SourceSpec] = field(default_factory=lambda: [SourceSpec()])
    train_split: str = "train"
    val_split: str = "val"
    sequencing: dict[str, float] = field(default_factory=lambda: {"none": 1.0, "partial": 1.0, "full": 1.0})
    variants: list[str] = field(default_factory=lambda: ["orig"])
    num_workers: int = field(default=0, metadata={"ge": 0, "le": MAX_WORKERS})
    cache: str = "disk"
    stream_order: bool = False


@dataclass(frozen=True)
class TrainSpec:
    """Loop settings shared by every stage.

    Ranges (refused with one line outside them): ``batch_size`` 1..:data:`MAX_BATCH_SIZE`,
    ``grad_clip`` > 0 or null, ``log_every``, ``checkpoint_every`` and ``steps_per_epoch`` >= 1,
    ``threads`` >= 1 or null; every number finite.

    Args:
        batch_size: Sequences per optimiser step; each is run twice (as captured and rotated).
        rotation: Global rotation of the second copy: ``so3``, ``yaw`` or ``none``.
        device: ``auto`` (CUDA when available), ``cpu`` or ``cuda``.
        amp: Mixed precision (bfloat16 autocast) for the U-Net on CUDA; the DLOE layer stays float32.
        dtype: Parameter dtype, ``float32`` or ``float64``.
        grad_clip: Clip the gradient norm to this value (None: off).
        log_every: Steps between log records.
        checkpoint_every: Steps between checkpoints (each stage's end is always checkpointed).
        steps_per_epoch: Steps that make one epoch (validation, plateau); None: one pass over the data.
        threads: CPU threads (torch and BLAS) of the training process when it trains on the CPU; None
            keeps the libraries' defaults. 1 is fastest on a shared or small machine (see
            :func:`gttnet.train.threads.limit_cpu_threads`); raise it on an idle many-core one.
    """

    batch_size: int = field(default=2, metadata={"ge": 1, "le": MAX_BATCH_SIZE})
    rotation: str = field(default="so3", metadata={"choices": ("so3", "yaw", "none")})
    device: str = "auto"
    amp: bool = False
    dtype: str = "float32"
    grad_clip: float | None = field(default=1.0, metadata={"gt": 0})
    log_every: int = field(default=10, metadata={"ge": 1})
    checkpoint_every: int = field(default=200, metadata={"ge": 1})
    steps_per_epoch: int | None = field(default=None, metadata={"ge": 1})
    threads: int | None = 1


@dataclass(frozen=True)
class TrainRecipe:
    """A complete training recipe.

    Args:
        name: Recipe name (run directory prefix).
        seed: Seed of the model initialisation, data order, sequencing draws and rotations.
        output_dir: The run folder itself (checkpoint, log, model); None: ``runs/<name>``. ``--out``
            overrides it. Where a run lives is no part of its identity: ``--resume`` ignores this key
            when it compares recipes. Older recipes named it ``out_dir`` (then the parent of
            timestamped run folders); they still load, with a warning, as ``output_dir: <out_dir>/<name>``.
        model: :class:`ModelSpec`.
        data: :class:`DataSpec`.
        train: :class:`TrainSpec`.
        stages: The cascade, run in order.
    """

    name: str
    stages: list[Stage]
    seed: int = field(default=0, metadata={"ge": 0, "lt": 2**32})
    output_dir: str | None = None
    model: ModelSpec = field(default_factory=ModelSpec)
    data: DataSpec = field(default_factory=DataSpec)
    train: TrainSpec = field(default_factory=TrainSpec)

    @classmethod
    def from_mapping(cls, data: dict, overrides: Sequence[str] = (), source: str = "") -> TrainRecipe:
        """:func:`parse_train_recipe` (the hook :func:`gttdata.recipe.load_recipe` calls)."""
        return parse_train_recipe(data, overrides, source)

    def __post_init__(self) -> None:
        if not self.stages:
            raise ValueError("stages must hold at least one stage")
        from gttnet.model.network import MODEL_BUILDERS, GTTNetConfig

        if self.model.builder not in MODEL_BUILDERS:
            raise ValueError(
                f"model.builder: unknown model builder {self.model.builder!r}; known: {sorted(MODEL_BUILDERS)}"
            )
        known = {f.name for f in dataclasses.fields(GTTNetConfig)}
        bad = sorted(set(self.model.settings) - known)
        if bad:
            raise ValueError(
                f"model.settings.{bad[0]}: unknown model setting; known: {', '.join(sorted(known))}"
            )
        if not self.data.sources:
            raise ValueError("data.sources must hold at least one source")
        bad = sorted(set(self.data.sequencing) - {"none", "partial", "full"})
        if bad or not any(w > 0 for w in self.data.sequencing.values()):
            raise ValueError(
                f"data.sequencing must weight some of none/partial/full, got {self.data.sequencing}"
            )
        if self.train.device not in ("auto", "cpu", "cuda"):
            raise ValueError(f"train.device must be auto, cpu or cuda, got {self.train.device!r}")
        if self.train.threads is not None and self.train.threads < 1:
            raise ValueError(f"train.threads must be >= 1 or null, got {self.train.threads}")
        if self.train.dtype not in ("float32", "float64"):
            raise ValueError(f"train.dtype must be float32 or float64, got {self.train.dtype!r}")


def parse_train_recipe(data: dict, overrides: Sequence[str] = (), source: str = "") -> TrainRecipe:
    """Build a :class:`TrainRecipe` from a plain mapping and ``key.sub=value`` overrides.

    Args:
        data: Plain recipe data (not modified).
        overrides: ``key.sub=value`` strings (values parsed as YAML), applied in order.
        source: The recipe file, first word of every message ("" for none).

    Raises:
        RecipeError: On an unknown key, a wrong type or an invalid value (one line naming the key), or
            both ``out_dir`` and ``output_dir`` in ``data``.

    Warns:
        FutureWarning: ``data`` uses the old key ``out_dir`` (one line naming ``source`` and the key).
    """
    data = yaml.safe_load(yaml.safe_dump(data)) or {}
    _rename_out_dir(data, source or "train recipe")
    apply_overrides(data, overrides, source or "train recipe")
    return build_dataclass(TrainRecipe, data, "", source)


def _rename_out_dir(data: dict, source: str) -> None:
    """Read the old key ``out_dir: P`` (parent of run folders) as ``output_dir: P/<name>``, with a warning."""
    if "out_dir" not in data:
        return
    if "output_dir" in data:
        raise RecipeError(
            f"{source}: out_dir and output_dir: expected one of them (out_dir is the old name), found both"
        )
    parent = data.pop("out_dir")
    if not isinstance(parent, str):
        raise RecipeError(f"{source}: out_dir: expected a folder path, found {parent!r}")
    data["output_dir"] = str(Path(parent) / str(data.get("name", "run")))
    warnings.warn(
        f"{source}: out_dir is deprecated, rename it output_dir (the run folder itself); "
        f"reading out_dir: {parent} as output_dir: {data['output_dir']}",
        FutureWarning,
        stacklevel=3,
    )


def run_folder(recipe: TrainRecipe) -> Path:
    """The run folder of ``recipe``: its ``output_dir``, or ``runs/<name>`` when it names none."""
    return Path(recipe.output_dir) if recipe.output_dir else Path("runs") / recipe.name


def saved_run_recipe(data: dict, run_dir: str | Path) -> TrainRecipe:
    """The recipe a run saved (checkpoint or ``recipe.yaml``), placed in ``run_dir`` where it now lives.

    Saved recipes are no user's file: an older run's ``out_dir`` key is dropped without a warning.
    """
    data = {k: v for k, v in data.items() if k not in ("out_dir", "output_dir")}
    return parse_train_recipe({**data, "output_dir": str(run_dir)}, source=f"{run_dir}: saved recipe")


def load_train_recipe(path: str | Path, overrides: Sequence[str] = ()) -> TrainRecipe:
    """``load_recipe(path, overrides, cls=TrainRecipe)`` (relative file paths resolve against its folder)."""
    return load_recipe(path, overrides, cls=TrainRecipe)


def recipe_to_dict(recipe: TrainRecipe) -> dict:
    """Plain (YAML/JSON-serialisable) form of a recipe; ``parse_train_recipe`` inverts it."""
    return dataclasses.asdict(recipe)
