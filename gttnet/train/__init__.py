"""GTT-Net training: recipes, cascade stages, the loop and checkpoints."""

from __future__ import annotations

from gttnet.train.loop import RunResult, train
from gttnet.train.recipe import TrainRecipe, load_train_recipe

__all__ = ["RunResult", "TrainRecipe", "load_train_recipe", "train"]
