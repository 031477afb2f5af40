"""CPU thread budget of a command: BLAS/OpenMP pools, OpenCV and (when loaded) torch; ``--threads``/``GTT_THREADS``.

Every numerical library starts one thread per core by default. On a machine that other work shares, each
small BLAS call then waits at a barrier for threads the kernel has descheduled: DLOE on a 2-core machine
shared with other jobs took 19 s with the default pools against 1.5 s with one thread. The budget here:

* ``--threads N`` (or ``GTT_THREADS=N``) sets it explicitly;
* otherwise ``min(cores, 4)`` less the cores the load average says other work keeps busy, at least 1
  (:func:`default_threads`), unless the user set ``OMP_NUM_THREADS``,
  ``OPENBLAS_NUM_THREADS`` or ``MKL_NUM_THREADS`` (then the libraries' own settings are left alone);
* worker processes (``--workers``) run one thread each unless ``--threads``/``GTT_THREADS`` says otherwise
  (:func:`limit_worker_threads`).

Start-up rule: this module imports only the standard library and click at module level; it never imports
numpy or torch itself. Before numpy is loaded, environment variables are enough (the pools read them when
they start); a library already loaded is limited with threadpoolctl, and torch with ``torch.set_num_threads``
only when torch is already imported.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import click

__all__ = [
    "ENV_VAR",
    "THREAD_ENV_VARS",
    "default_threads",
    "parse_threads",
    "requested_threads",
    "set_threads",
    "limit_worker_threads",
    "threads_option",
]

F = TypeVar("F", bound=Callable[..., Any])

#: The environment variable that sets the budget when ``--threads`` is not given.
ENV_VAR = "GTT_THREADS"

#: Variables the thread pools of OpenMP, OpenBLAS, MKL, BLIS, Accelerate, numexpr and OpenCV read at start.
THREAD_ENV_VARS = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "BLIS_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "OPENCV_FOR_THREADS_NUM",
)

#: Upper bound of the default: past 4 threads the small matrices of a reconstruction gain nothing.
MAX_DEFAULT_THREADS = 4

_STATE: dict[str, Any] = {"requested": None, "limiter": None}


def usable_cores() -> int:
    """Return the number of CPU cores this process may run on (its affinity mask, else ``os.cpu_count()``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - macOS / Windows
        return max(1, os.cpu_count() or 1)


def busy_cores() -> int:
    """Return the cores other work keeps busy: the 1-minute load average, rounded (0 where unknown)."""
    try:
        return int(os.getloadavg()[0] + 0.5)
    except (AttributeError, OSError):  # pragma: no cover - no load average on this platform
        return 0


def default_threads() -> int:
    """Return the default budget: ``min(cores, 4)`` less the cores other work keeps busy, at least 1.

    On a machine that other jobs load, threads beyond the idle cores only wait for each other: on the shared
    2-core machine (load 13), DLOE on 301 images solved in 28.4 s with 2 threads and 8.7 s with 1
    (``benchmarks/bench_threads.py``).

    Example:
        >>> 1 <= default_threads() <= 4
        True
    """
    cores = usable_cores()
    return max(1, min(cores, MAX_DEFAULT_THREADS, cores - busy_cores()))


def parse_threads(text: str | int, source: str = "--threads") -> int:
    """Parse a thread count; ``source`` names where it came from in the error.

    Args:
        text: The value given (``"2"``, ``2``).
        source: ``"--threads"`` or the environment variable's name.

    Returns:
        The count, >= 1.

    Raises:
        click.ClickException: Not a whole number >= 1 (one line naming ``source``, expected and found).

    Example:
        >>> parse_threads(" 3 ")
        3
    """
    try:
        n = int(str(text).strip())
    except ValueError:
        n = 0
    if n < 1:
        raise click.ClickException(f"{source}: expected a whole number of threads >= 1, got {str(text)!r}")
    return n


def requested_threads() -> int | None:
    """Return the count given by ``--threads`` or ``GTT_THREADS`` to this process, or None (the default)."""
    return _STATE["requested"]


def set_threads(n: int) -> None:
    """Use at most ``n`` threads in BLAS/OpenMP pools, OpenCV and torch, now and in libraries loaded later.

    Sets the pools' environment variables (read when a library loads; inherited by worker processes), limits
    the BLAS/OpenMP libraries already loaded with threadpoolctl, and calls ``torch.set_num_threads`` and
    ``cv2.setNumThreads`` only when those modules are already imported (nothing heavy is imported here).

    Args:
        n: Thread count, >= 1.
    """
    if n < 1:
        raise ValueError(f"threads must be >= 1, got {n}")
    for var in THREAD_ENV_VARS:
        os.environ[var] = str(n)
    if "numpy" in sys.modules or "scipy" in sys.modules or "torch" in sys.modules:
        from threadpoolctl import threadpool_limits

        _STATE["limiter"] = threadpool_limits(limits=n)  # kept alive for the life of the process
    if "torch" in sys.modules:
        torch = sys.modules["torch"]
        if torch.get_num_threads() != n:
            torch.set_num_threads(n)
    if "cv2" in sys.modules:
        sys.modules["cv2"].setNumThreads(n)


def limit_worker_threads() -> None:
    """Thread budget of a worker process (call it from a pool initializer).

    One thread, unless the parent command was given ``--threads``/``GTT_THREADS`` (inherited through the
    environment): then that count per worker.
    """
    value = os.environ.get(ENV_VAR, "").strip()
    set_threads(parse_threads(value, ENV_VAR) if value else 1)


def _apply(ctx: click.Context, _param: click.Parameter, value: str | None) -> None:
    if ctx.resilient_parsing:
        return
    if value is not None:
        n: int | None = parse_threads(value, "--threads")
    else:
        env = os.environ.get(ENV_VAR)
        n = parse_threads(env, ENV_VAR) if env is not None else None
    _STATE["requested"] = n
    if n is None:
        if not any(var in os.environ for var in THREAD_ENV_VARS[:3]):  # else the user chose: keep it
            set_threads(default_threads())
    else:
        os.environ[ENV_VAR] = str(n)  # worker processes inherit the explicit count
        set_threads(n)


def threads_option(f: F) -> F:
    """Add ``--threads N`` to a command (default: ``GTT_THREADS``, else :func:`default_threads`).

    The value is applied before the command body runs (an eager option: before the other options'
    callbacks too), so the libraries the command loads start with the budget. The command reads the
    explicit count, if any, with :func:`requested_threads`.
    """
    return click.option(
        "--threads",
        metavar="N",
        default=None,
        is_eager=True,
        expose_value=False,
        callback=_apply,
        help=f"CPU threads of BLAS/OpenMP/torch [default: ${ENV_VAR}, else min(cores, {MAX_DEFAULT_THREADS}) "
        "less the busy cores, at least 1].",
    )(f)
