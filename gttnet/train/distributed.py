"""Devices and DDP for training: device selection, process-group setup, run-directory agreement, replica checks."""

from __future__ import annotations

import os
from pathlib import Path

import torch
import torch.distributed as dist

__all__ = ["select_device", "setup", "teardown", "agree_on_path", "wrap", "check_replicas"]

#: Whether :func:`setup` created the process group (only then does :func:`teardown` destroy it).
_OWNED = False


def select_device(name: str, *, local_rank: int = 0) -> torch.device:
    """``auto`` → CUDA when available (this process's local GPU under torchrun), else CPU."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda":
        if not torch.cuda.is_available():
            raise ValueError("device 'cuda' requested but CUDA is not available; use --device cpu or auto")
        return torch.device("cuda", local_rank)
    return torch.device(name)


def setup(device_name: str) -> tuple[int, int, int]:
    """Join the torchrun process group when ``WORLD_SIZE > 1`` (NCCL on GPUs, else gloo).

    Returns:
        ``(rank, world_size, local_rank)``; ``(0, 1, 0)`` for a single process.
    """
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, 0
    local = int(os.environ.get("LOCAL_RANK", "0"))
    if not dist.is_initialized():
        global _OWNED
        use_nccl = device_name != "cpu" and torch.cuda.is_available()
        if use_nccl:
            torch.cuda.set_device(local)
        dist.init_process_group(backend="nccl" if use_nccl else "gloo")
        _OWNED = True
    return dist.get_rank(), dist.get_world_size(), local


def teardown(world: int) -> None:
    """Leave the process group :func:`setup` created: wait for every rank, then destroy it.

    Left to the interpreter's exit, the group's gloo threads could still be running when their objects
    were destroyed, and a rank died with ``terminate called without an active exception`` (SIGABRT)
    after the run had finished (``test_ddp_two_processes_gloo`` failed that way now and then).
    """
    global _OWNED
    if world > 1 and _OWNED and dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()
        _OWNED = False


def agree_on_path(path: str | Path, world: int) -> Path:
    """Rank 0's ``path`` on every rank (a timestamped run directory must be one directory)."""
    box = [str(path)]
    if world > 1:
        dist.broadcast_object_list(box, src=0)
    return Path(box[0])


def wrap(module: torch.nn.Module, dev: torch.device, world: int) -> torch.nn.Module:
    """``module`` in DistributedDataParallel when ``world > 1``, else unchanged."""
    if world <= 1:
        return module
    ids = [dev.index] if dev.type == "cuda" else None
    return torch.nn.parallel.DistributedDataParallel(module, device_ids=ids, find_unused_parameters=True)


def check_replicas(model: torch.nn.Module, world: int) -> None:
    """Under DDP every rank must end with the same weights (gradients were all-reduced).

    Raises:
        RuntimeError: If the ranks' parameter sums differ.
    """
    if world <= 1:
        return
    total = torch.stack([p.detach().double().sum() for p in model.parameters()]).sum().reshape(1)
    sums = [torch.zeros_like(total) for _ in range(world)]
    dist.all_gather(sums, total)
    if any(not torch.equal(s, sums[0]) for s in sums):
        raise RuntimeError(f"DDP replicas diverged: parameter sums {[float(s) for s in sums]}")
