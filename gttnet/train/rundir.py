"""The run directory of a training run: refuse to mix runs, resume the same recipe, replace on request.

The convention is the CLI's (``--resume`` / ``--overwrite``):

- a run directory that already holds a run is refused unless one of the two is given;
- ``resume`` continues the run from its checkpoint, and only if it was started by the same recipe
  (execution settings such as ``train.threads`` may differ; a directory without a checkpoint starts afresh);
- ``overwrite`` deletes the earlier run's files first, so two runs' logs never mix.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from gttdata.errors import OutputError
from gttdata.fileio import check_output, refuse_foreign_output, remove_output
from gttnet.train.checkpoint import CHECKPOINT_NAME, load_checkpoint
from gttnet.train.recipe import TrainRecipe, recipe_to_dict, saved_run_recipe

__all__ = ["RUN_FILES", "holds_run", "open_run"]

#: Files and folders a training run writes into its directory (what ``overwrite`` removes).
RUN_FILES = (
    CHECKPOINT_NAME,
    "model.pt",
    "model.json",
    "log.jsonl",
    "loss_curve.png",
    "recipe.yaml",
    "tensorboard",
    "item_cache",
)


def holds_run(run_dir: Path) -> bool:
    """Whether ``run_dir`` holds (part of) a training run."""
    return any((run_dir / name).exists() for name in RUN_FILES)


def _first_difference(a: object, b: object, where: str = "") -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b), key=str):
            if a.get(key) != b.get(key):
                return _first_difference(a.get(key), b.get(key), f"{where}.{key}" if where else str(key))
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            if x != y:
                return _first_difference(x, y, f"{where}.{i}" if where else str(i))
    return f"{where or 'recipe'}: this recipe has {b!r}, the run has {a!r}"


#: How a run is executed, not what it learns: a run resumes with other values of these (more threads or
#: data workers on another machine; the device is a ``--device`` option, not part of the recipe's identity).
EXECUTION_SETTINGS = (("train", "threads"), ("data", "num_workers"))


def _identity(recipe: TrainRecipe) -> dict:
    """What makes two runs the same run: the recipe except where it lives and :data:`EXECUTION_SETTINGS`."""
    out = {k: v for k, v in recipe_to_dict(recipe).items() if k != "output_dir"}
    for section, key in EXECUTION_SETTINGS:
        if isinstance(out.get(section), dict):
            out[section] = {k: v for k, v in out[section].items() if k != key}
    return out


def open_run(
    recipe: TrainRecipe | None,
    *,
    out: str | Path,
    resume: bool = False,
    overwrite: bool = False,
) -> tuple[TrainRecipe, dict | None]:
    """Decide what a training call does with its run directory.

    Args:
        recipe: The recipe, or None to resume the run in ``out`` with its saved recipe.
        out: The run directory.
        resume: Continue the run in ``out`` when there is one (only a run of the same recipe).
        overwrite: Delete an earlier run in ``out`` first.

    Returns:
        ``(recipe, checkpoint payload or None)``; the recipe's ``output_dir`` is ``out``.

    Raises:
        OutputError: ``out`` holds a run and neither flag is given, or holds a run of another recipe, or
            ``out`` holds a gttdata dataset.
        FileNotFoundError: ``recipe`` is None and ``out`` holds no checkpoint to resume from.
    """
    run_dir = Path(out)
    refuse_foreign_output(run_dir, writer="gttnet train")  # whatever the flags: never touch a dataset
    if recipe is None:
        if not resume:
            raise ValueError("train() needs a recipe, or resume=True to continue the run in out")
        saved_run = load_checkpoint(run_dir)
        return saved_run_recipe(saved_run["recipe"], run_dir), saved_run
    recipe = dataclasses.replace(recipe, output_dir=str(run_dir))
    check_output(
        run_dir, exists=holds_run(run_dir), resume=bool(resume), overwrite=overwrite, what="a training run"
    )
    if overwrite:
        remove_output([run_dir / name for name in RUN_FILES])
        return recipe, None
    payload: dict | None = None
    if resume and (run_dir / CHECKPOINT_NAME).is_file():
        payload = load_checkpoint(run_dir)
        saved = _identity(saved_run_recipe(payload["recipe"], run_dir))
    elif resume and (run_dir / "recipe.yaml").is_file():
        import yaml

        saved = _identity(saved_run_recipe(yaml.safe_load((run_dir / "recipe.yaml").read_text()), run_dir))
    else:
        saved = None
    if saved is not None and saved != _identity(recipe):
        raise OutputError(
            f"{run_dir}: holds a run of another recipe ({_first_difference(saved, _identity(recipe))}); "
            f"resume it with its own recipe (gttnet train --out {run_dir} --resume), or use another --out "
            "or --overwrite"
        )
    if resume and payload is None:  # started but never checkpointed: nothing to keep
        remove_output([run_dir / name for name in RUN_FILES])
    return recipe, payload
