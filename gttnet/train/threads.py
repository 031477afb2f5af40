"""CPU thread budget of a training process: torch's intra-op pool and the BLAS behind numpy/scipy."""

from __future__ import annotations

import logging

import torch

__all__ = ["limit_cpu_threads"]

log = logging.getLogger(__name__)

_LIMITER = None  # keeps threadpoolctl's limits alive for the life of the process


def limit_cpu_threads(n: int | None) -> None:
    """Use at most ``n`` threads in torch and in the BLAS libraries loaded so far (None: leave as is).

    A training step is many small kernels (a few thousand images x 21 slots x <= 31 points) and, on the
    sparse X-step path, numpy/scipy calls on small matrices. With more threads than free cores, every
    kernel's thread barrier waits for a descheduled thread: on the shared 2-core CI machine, 2 torch
    threads plus OpenBLAS's own pool made a step up to 10x slower than one thread
    (``benchmarks/bench_train_step.py``). DataLoader workers already run torch single-threaded.

    Args:
        n: Thread count (>= 1), or None to keep the libraries' defaults.
    """
    global _LIMITER
    if n is None:
        return
    if n < 1:
        raise ValueError(f"threads must be >= 1, got {n}")
    torch.set_num_threads(n)
    from threadpoolctl import threadpool_limits

    _LIMITER = threadpool_limits(limits=n, user_api="blas")
    log.debug("CPU threads limited to %d (torch and BLAS)", n)
