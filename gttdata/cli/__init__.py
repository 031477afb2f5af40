"""The ``gttdata`` command group; each subcommand lives in its own module.

Start-up rule (``gttdata --help`` must answer in well under 0.3 s): a module in this package imports only
the standard library, click and ``gttdata.cli``/``gttdata.errors`` at module level. Everything heavier
(numpy, scipy, OpenCV, h5py, matplotlib, yaml, tqdm, and the library modules that pull them in) is imported inside the command's function body,
or inside the helper that needs it::

    @click.command("mycmd")
    def mycmd_cmd(...):
        from gttdata.something import do_it  # imported only when the command runs

        do_it(...)

Type-only names go under ``if TYPE_CHECKING:``. ``tests/test_startup.py`` fails when ``import gttdata.cli``
loads any of them, and ``benchmarks/bench_startup.py`` times ``--help``.
"""

from __future__ import annotations

import click

from gttdata._cli_common import install_warning_lines, version_option
from gttdata.errors import friendly_errors

__all__ = ["main", "friendly_errors"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@version_option("gttdata", ("gtt", "numpy", "scipy", "h5py", "opencv-python-headless", "click", "pyyaml"))
def main() -> None:
    """Simulate unsynchronized multi-camera captures from mocap and write them as HDF5 shards."""
    install_warning_lines()


# Each subcommand module adds itself to ``main`` (imported after ``main`` exists; a missing one fails loudly).
from gttdata.cli import export, generate, inspect, motions, preview, verify  # noqa: E402

for _module in (motions, generate, inspect, verify, preview, export):
    _module.register(main)
