"""Checkpoints: save and restore ALL training state (model, optimiser, cascade position, RNG, recipe)."""

from __future__ import annotations

import random
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from gttnet.errors import ModelError
from gttnet.model.files import CHECKPOINT_FORMAT, load_checked, model_config_dict, save_checked

__all__ = [
    "LoopState",
    "rng_states",
    "set_rng_states",
    "save_checkpoint",
    "load_checkpoint",
    "CHECKPOINT_NAME",
]

CHECKPOINT_NAME = "checkpoint.pt"


@dataclass
class LoopState:
    """Where the cascade is, and the schedule state of the current stage.

    Args:
        stage_index: Index of the running stage.
        stage_step: Steps done in that stage.
        global_step: Steps done over all stages.
        keys_consumed: Training keys this rank has drawn from the data stream (data position).
        lr: Current learning rate.
        best_val: Best validation loss of the stage (plateau schedule).
        bad_vals: Validations since the last improvement.
        history: Logged records (train and validation), for the loss curve.
    """

    stage_index: int = 0
    stage_step: int = 0
    global_step: int = 0
    keys_consumed: int = 0
    lr: float = 0.0
    best_val: float = float("inf")
    bad_vals: int = 0
    history: list[dict] = field(default_factory=list)


def rng_states() -> dict:
    """States of the python, numpy, torch and (when present) CUDA generators, as plain types.

    Everything is a tensor, number, string, tuple or dict, so a checkpoint loads with
    ``torch.load(weights_only=True)``: the NumPy Mersenne-Twister key (624 ``uint32``) is stored as an
    int64 tensor, never as a pickled ``ndarray``.
    """
    name, key, pos, has_gauss, cached = np.random.get_state()  # noqa: NPY002 (global state)
    out = {
        "python": random.getstate(),
        "numpy": {
            "bit_generator": str(name),
            "key": torch.from_numpy(np.asarray(key, dtype=np.int64)),
            "pos": int(pos),
            "has_gauss": int(has_gauss),
            "cached_gaussian": float(cached),
        },
        "torch": torch.get_rng_state(),
    }
    if torch.cuda.is_available():
        out["cuda"] = torch.cuda.get_rng_state_all()
    return out


def _numpy_state(saved: object) -> tuple:
    """The ``np.random.set_state`` tuple of a saved NumPy state (plain dict, or the tuple of format 2)."""
    if isinstance(saved, dict):
        key = saved["key"]
        key = key.numpy() if isinstance(key, torch.Tensor) else np.asarray(key)
        return (
            str(saved["bit_generator"]),
            key.astype(np.uint32),
            int(saved["pos"]),
            int(saved["has_gauss"]),
            float(saved["cached_gaussian"]),
        )
    return tuple(saved)  # type: ignore[arg-type]  # format 2: ('MT19937', ndarray, pos, has_gauss, cached)


def set_rng_states(states: dict) -> None:
    """Restore generator states saved by :func:`rng_states` (or by format-2 checkpoints)."""
    random.setstate(states["python"])
    np.random.set_state(_numpy_state(states["numpy"]))  # noqa: NPY002
    torch.set_rng_state(states["torch"])
    if "cuda" in states and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(states["cuda"])


def save_checkpoint(
    run_dir: str | Path,
    *,
    model: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    state: LoopState,
    recipe: dict,
) -> Path:
    """Write ``run_dir/checkpoint.pt`` atomically, with a SHA-256 header (:func:`gttnet.model.files.save_checked`).

    Args:
        run_dir: Run directory.
        model: The (unwrapped) model.
        optimizer: The current stage's optimiser.
        state: Cascade position and schedule.
        recipe: The resolved recipe as a plain mapping.

    Returns:
        The checkpoint path.
    """
    path = Path(run_dir) / CHECKPOINT_NAME
    payload = {
        "format": CHECKPOINT_FORMAT,
        "model": model.state_dict(),
        "model_config": model_config_dict(model),
        "optimizer": optimizer.state_dict(),
        "state": asdict(state),
        "rng": rng_states(),
        "recipe": recipe,
    }
    return save_checked(path, payload)


def load_checkpoint(run_dir: str | Path) -> dict:
    """Read ``run_dir/checkpoint.pt`` (CPU tensors) with ``state`` as a :class:`LoopState`.

    The file's SHA-256 header is checked first: a corrupt checkpoint never resumes. It is read weights
    only (:func:`gttnet.model.files.load_checked`): a checkpoint that would run code is refused.

    Raises:
        FileNotFoundError: If the run directory has no checkpoint.
        ModelError: An empty, truncated, bit-flipped, unreadable or code-carrying checkpoint (one line).
    """
    path = Path(run_dir) / CHECKPOINT_NAME
    if not path.is_file():
        raise FileNotFoundError(2, "no checkpoint to resume from", str(path))
    payload = load_checked(path)
    try:
        payload["state"] = LoopState(**payload["state"])
    except (KeyError, TypeError) as exc:
        raise ModelError(f"{path}: expected a training checkpoint with a loop state, found {exc}") from exc
    try:
        _numpy_state(payload["rng"]["numpy"])
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise ModelError(
            f"{path}: rng.numpy: expected the NumPy generator state, found {exc.__class__.__name__}: {exc}"
        ) from exc
    return payload
