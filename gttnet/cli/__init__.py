"""The ``gttnet`` command group; each subcommand lives in its own module.

Start-up rule (``gttnet --help`` must answer in well under 0.3 s): a module in this package imports only
the standard library, click and ``gttdata.cli``/``gttdata.errors`` at module level. Everything heavier
(torch, numpy, scipy, OpenCV, h5py, matplotlib, yaml, tqdm, and the library modules that pull them in) is imported inside the command's function body,
or inside the helper that needs it::

    @click.command("mycmd")
    def mycmd_cmd(...):
        from gttnet.something import do_it  # imported only when the command runs

        do_it(...)

Type-only names go under ``if TYPE_CHECKING:``. ``tests/test_startup.py`` fails when ``import gttnet.cli``
loads any of them, and ``benchmarks/bench_startup.py`` times ``--help``.
"""

from __future__ import annotations

import click

from gttdata._cli_common import install_warning_lines, version_option

__all__ = ["main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@version_option("gttnet", ("gtt", "torch", "numpy", "scipy"))
def main() -> None:
    """Reconstruct dynamic 3D skeletons from unsynchronized multi-camera 2-D observations."""
    install_warning_lines()


# Each subcommand module adds itself to ``main`` (imported after ``main`` exists; a missing one fails loudly).
from gttnet.cli import batch, evaluate, export_json, reconstruct, render, segment, sync, train  # noqa: E402

for _module in (reconstruct, sync, batch, train, evaluate, segment, render, export_json):
    _module.register(main)
