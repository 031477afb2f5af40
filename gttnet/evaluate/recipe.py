"""EvalRecipe: the typed form of a ``recipes/gttnet/eval_*.yaml`` file, with ``key.sub=value`` overrides."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from gttdata.capture.views import SEQUENCING
from gttdata.errors import RecipeError
from gttdata.recipe import apply_overrides, build_dataclass, load_recipe

__all__ = [
    "EvalRecipeError",
    "DataSpec",
    "SweepValue",
    "SweepSpec",
    "MethodEntry",
    "RuntimeSpec",
    "EvalRecipe",
    "PAPER_SWEEPS",
    "load_eval_recipe",
    "parse_eval_recipe",
    "apply_overrides",
]


class EvalRecipeError(RecipeError):
    """An evaluation recipe is malformed (names the key, what was expected and what was found)."""


@dataclass(frozen=True)
class DataSpec:
    """Where the test sequences come from: a generate recipe built in memory, or a dataset directory.

    Args:
        generate: A ``gttdata`` generate recipe (YAML path); samples are built with ``build_sample``.
        dataset: A generated dataset directory (with ``manifest.json``); exclusive with ``generate``.
        split: Split to draw the sequences from.
        n_sequences: Number of sequences (samples ``0 .. n-1``); None = the whole split.
        overrides: ``key=value`` overrides of the generate recipe applied to every condition.
        variant: Stored variant to evaluate (``"orig"`` or an augmentation name).
    """

    generate: str | None = field(default=None, metadata={"path": True})
    dataset: str | None = field(default=None, metadata={"path": True})
    split: str = "test"
    n_sequences: int | None = field(default=None, metadata={"ge": 1})
    overrides: list[str] = field(default_factory=list)
    variant: str = "orig"

    def __post_init__(self) -> None:
        if (self.generate is None) == (self.dataset is None):
            raise ValueError("give exactly one of generate (a gttdata recipe) or dataset (a directory)")
        if self.n_sequences is not None and self.n_sequences < 1:
            raise ValueError(f"n_sequences must be >= 1, got {self.n_sequences}")


@dataclass(frozen=True)
class SweepValue:
    """One value of a sweep and the extra generate-recipe overrides it needs.

    Args:
        value: The swept variable's value (written to ``errors.csv``).
        overrides: Extra ``key=value`` overrides for this value only (e.g. a longer window at 7.5 Hz).
        dataset: A dataset directory holding this condition (dataset sources only).
    """

    value: float
    overrides: list[str] = field(default_factory=list)
    dataset: str | None = field(default=None, metadata={"path": True})


@dataclass(frozen=True)
class SweepSpec:
    """One swept variable, each value applied as a generate-recipe override with the others at default.

    Args:
        name: Condition name (``noise``, ``frame_rate``, ``missing``...).
        variable: The generate-recipe key the value overrides (e.g. ``capture.sigma_px``).
        values: Values (numbers, or mappings ``{value, overrides, dataset}``).
        label: Axis label of the plot.
        scale: Factor from recipe units to plotted/recorded units (e.g. 100 for drop rate -> %).
    """

    name: str
    variable: str
    values: list[SweepValue]
    label: str = ""
    scale: float = 1.0


@dataclass(frozen=True)
class MethodEntry:
    """A method column of the evaluation: a registered method plus options.

    Args:
        name: Column name in the outputs (defaults to ``method``).
        method: Registered reconstruction method (``pseudo``, ``dloe``, ``dct``, ``hpf``, ``gttnet``).
        options: Method options, e.g. ``{model: runs/x/model.pt, top_q: 3}`` (GTT-Net top-Q at test).
        note: Free text recorded with every skip of this method (e.g. how to train the missing model).
    """

    name: str = ""
    method: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    note: str = ""

    def __post_init__(self) -> None:
        if not self.method and not self.name:
            raise ValueError("a method entry needs method (or name)")
        object.__setattr__(self, "method", self.method or self.name)
        object.__setattr__(self, "name", self.name or self.method)


@dataclass(frozen=True)
class RuntimeSpec:
    """The runtime study: time per sequence against the number of images (paper Fig. 5a).

    Args:
        lengths: Sequence lengths in images.
        methods: Methods to time (GTT-Net falls back to an untrained network when no model exists).
        generate: Generate recipe whose test motions are long enough (window set per length).
        split: Split to draw from.
        repeats: Timed runs per sequence and length.
        sequences: Test sequences timed per length (samples ``0..sequences-1`` of ``split``); the study
            reports the median over sequences and repeats, with min..max.
        sequencing: Sequencing condition of the timed runs.
        model: Trained GTT-Net model path; None = bundled, or untrained when none is installed.
        device: Device of the GTT-Net timing (``"cpu"`` or ``"cuda"``); the classical methods run on the CPU.
    """

    lengths: list[int] = field(default_factory=lambda: [100, 200, 300, 400, 500, 600])
    methods: list[str] = field(default_factory=lambda: ["dloe", "gttnet"])
    generate: str = field(default="recipes/gttdata/paper.yaml", metadata={"path": True})
    split: str = "test"
    repeats: int = field(default=1, metadata={"ge": 1})
    sequences: int = field(default=1, metadata={"ge": 1})
    sequencing: str = "none"
    model: str | None = field(default=None, metadata={"path": True})
    device: str = "cpu"


@dataclass(frozen=True)
class EvalRecipe:
    """A full evaluation: data, sweeps, sequencing conditions, methods and outputs.

    Args:
        name: Run name.
        output_dir: Run directory (``errors.csv``, ``summary.md``, plots).
        data: :class:`DataSpec`.
        sweeps: Swept conditions; empty = one ``base`` condition.
        sequencing: Sequencing conditions to run each method under.
        methods: Method entries (a bare string is a method name).
        workers: Worker processes over (condition, sample) jobs.
        error_bars: ``ci95`` (95% t-interval of the mean) or ``std`` in the plots of the mean.
        plot_statistic: ``mean`` (bars: ``error_bars``) or ``median`` (bars: interquartile range), robust
            to a sequence whose subject leaves every camera's view.
        seed: Seed of the image shuffle under sequencing ``none`` (None = from the sample name).
        runtime: Optional runtime study run after the sweeps.
    """

    name: str
    output_dir: str
    data: DataSpec
    sweeps: list[SweepSpec] = field(default_factory=list)
    sequencing: list[str] = field(default_factory=lambda: list(SEQUENCING))
    methods: list[MethodEntry] = field(default_factory=list)
    workers: int = field(default=1, metadata={"ge": 1, "le": 1024})
    error_bars: str = "ci95"
    plot_statistic: str = "mean"
    seed: int | None = field(default=None, metadata={"ge": 0, "lt": 2**32})
    runtime: RuntimeSpec | None = None

    #: The error type :func:`gttdata.recipe.load_recipe` raises for this recipe.
    recipe_error: ClassVar[type[RecipeError]] = EvalRecipeError

    @classmethod
    def from_mapping(cls, data: dict, overrides: Sequence[str] = (), source: str = "") -> EvalRecipe:
        """:func:`parse_eval_recipe` (the hook :func:`gttdata.recipe.load_recipe` calls)."""
        return parse_eval_recipe(data, overrides, source)

    def __post_init__(self) -> None:
        bad = [s for s in self.sequencing if s not in SEQUENCING]
        if bad or not self.sequencing:
            raise ValueError(f"sequencing must be a non-empty list of {SEQUENCING}, got {self.sequencing}")
        if not self.methods:
            raise ValueError("methods must name at least one method")
        names = [m.name for m in self.methods]
        if len(set(names)) != len(names):
            raise ValueError(f"method names must be unique, got {names}")
        if self.error_bars not in ("ci95", "std"):
            raise ValueError(f"error_bars must be ci95 or std, got {self.error_bars!r}")
        if self.plot_statistic not in ("mean", "median"):
            raise ValueError(f"plot_statistic must be mean or median, got {self.plot_statistic!r}")
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        if self.data.dataset is not None and any(v.dataset is None for s in self.sweeps for v in s.values):
            raise ValueError("a dataset source cannot apply sweep overrides: give each sweep value a dataset")


#: The paper's sweeps (Fig. 3): noise sigma, per-camera frame rate, missing joints.
PAPER_SWEEPS: list[dict] = [
    {
        "name": "noise",
        "variable": "capture.sigma_px",
        "label": "2-D noise sigma [px]",
        "values": [0, 1, 2, 3, 4, 5],
    },
    {
        "name": "frame_rate",
        "variable": "capture.fps_hz",
        "label": "frame rate per camera [Hz]",
        "values": [7.5, 15, 30],
    },
    {
        "name": "missing",
        "variable": "capture.joint_drop_rate",
        "label": "missing joints [%]",
        "scale": 100.0,
        "values": [0.0, 0.1, 0.2, 0.3, 0.4, 0.5],
    },
]


def _shorthand(tp: object, value: object) -> object:
    """A sweep value may be a bare number, a method entry a bare method name."""
    if tp is SweepValue and not isinstance(value, dict):
        return {"value": value}
    if tp is MethodEntry and isinstance(value, str):
        return {"method": value}
    return value


def parse_eval_recipe(data: dict, overrides: Sequence[str] = (), source: str = "") -> EvalRecipe:
    """Validate a raw recipe mapping (``sweeps: paper`` expands to :data:`PAPER_SWEEPS`).

    Args:
        data: Plain recipe data (not modified).
        overrides: ``key.sub=value`` strings.
        source: The recipe file, first word of every message ("" for none).

    Raises:
        EvalRecipeError: One line naming the key.
    """
    data = copy.deepcopy(dict(data))
    for step in range(2):  # expand before the overrides (so they can index it) and after (sweeps=paper)
        if data.get("sweeps") == "paper":
            data["sweeps"] = copy.deepcopy(PAPER_SWEEPS)
        if step == 0:
            data = apply_overrides(data, overrides, source or "evaluation recipe", error=EvalRecipeError)
    return build_dataclass(EvalRecipe, data, "", source, error=EvalRecipeError, shorthand=_shorthand)


def load_eval_recipe(path: str | Path, overrides: Sequence[str] = ()) -> EvalRecipe:
    """``load_recipe(path, overrides, cls=EvalRecipe)`` (relative file paths resolve against its folder).

    Raises:
        EvalRecipeError: e.g. ``eval_smoke.yaml: data.n_seq: unknown key (expected one of: ...)``.
    """
    return load_recipe(path, overrides, cls=EvalRecipe)
