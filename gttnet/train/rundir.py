"""The run directory of a training run: refuse to mix runs, resume the same recipe, replace on request.

The convention is the CLI's (``--resume`` / ``--overwrite``):

- a run directory that already holds a run is refused unless one of the two is given;
- ``resume`` continues the run from its checkpoint, and only if it was started by the same recipe
  (a directory without a checkpoint starts afresh);
- ``overwrite`` deletes the earlier run's files first, so two runs' logs never mix.
"""

from __future__ import annotations

from pathlib import Path

from gttdata.errors import OutputError
from gttdata.fileio import check_output, remove_output
from gttnet.train.checkpoint import CHECKPOINT_NAME, load_checkpoint
from gttnet.train.recipe import TrainRecipe, parse_train_recipe, recipe_to_dict

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


def open_run(
    recipe: TrainRecipe | None,
    *,
    out: str | Path | None,
    resume: bool | str | Path | None = None,
    overwrite: bool = False,
) -> tuple[TrainRecipe, dict | None, Path | None]:
    """Decide what a training call does with its run directory.

    Args:
        recipe: The recipe, or None to resume a run directory with its saved recipe.
        out: The run directory (None: a new timestamped one, decided later).
        resume: True: continue the run in ``out`` when there is one. A path: continue that run
            directory (``out`` must be None or the same).
        overwrite: Delete an earlier run in ``out`` first.

    Returns:
        ``(recipe, checkpoint payload or None, run directory or None)``.

    Raises:
        OutputError: ``out`` holds a run and neither flag is given, or holds a run of another recipe.
        FileNotFoundError: A resume path without a checkpoint.
    """
    if resume is not None and not isinstance(resume, bool):
        if out is not None and Path(out) != Path(resume):
            raise OutputError(f"--resume {resume} and --out {out}: give one run directory")
        out = Path(resume)
        if recipe is None:
            saved_run = load_checkpoint(out)
            return parse_train_recipe(saved_run["recipe"]), saved_run, out
        resume = True
    if recipe is None:
        raise ValueError("train() needs a recipe or a run directory to resume")
    if out is None:
        return recipe, None, None
    run_dir = Path(out)
    check_output(
        run_dir, exists=holds_run(run_dir), resume=bool(resume), overwrite=overwrite, what="a training run"
    )
    if overwrite:
        remove_output([run_dir / name for name in RUN_FILES])
        return recipe, None, run_dir
    payload: dict | None = None
    if resume and (run_dir / CHECKPOINT_NAME).is_file():
        payload = load_checkpoint(run_dir)
        saved = recipe_to_dict(parse_train_recipe(payload["recipe"]))
    elif resume and (run_dir / "recipe.yaml").is_file():
        import yaml

        saved = recipe_to_dict(parse_train_recipe(yaml.safe_load((run_dir / "recipe.yaml").read_text())))
    else:
        saved = None
    if saved is not None and saved != recipe_to_dict(recipe):
        raise OutputError(
            f"{run_dir}: holds a run of another recipe ({_first_difference(saved, recipe_to_dict(recipe))}); "
            "resume it with its own recipe (gttnet train --resume RUN_DIR), or use another --out or --overwrite"
        )
    if resume and payload is None:  # started but never checkpointed: nothing to keep
        remove_output([run_dir / name for name in RUN_FILES])
    return recipe, payload, run_dir
