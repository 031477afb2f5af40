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

__all__ = ["main"]


def _versions() -> str:
    out = []
    import importlib.metadata as md  # metadata lookups cost tens of ms: only on --version

    for n in ("gtt", "torch", "numpy", "scipy"):
        try:
            out.append(f"{n} {md.version(n)}")
        except md.PackageNotFoundError:
            out.append(f"{n} (not installed)")
    return ", ".join(out)


def _print_version(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if not value or ctx.resilient_parsing:
        return
    click.echo(f"gttnet {_versions()}")
    ctx.exit()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option(
    "--version",
    is_flag=True,
    expose_value=False,
    is_eager=True,
    callback=_print_version,
    help="Show the versions of gtt and its main dependencies, then exit.",
)
def main() -> None:
    """Reconstruct dynamic 3D skeletons from unsynchronized multi-camera 2-D observations."""


# Each subcommand module adds itself to ``main`` (imported after ``main`` exists; a missing one fails loudly).
from gttnet.cli import evaluate, export_json, reconstruct, render, segment, sync, train  # noqa: E402

for _module in (reconstruct, sync, train, evaluate, segment, render, export_json):
    _module.register(main)
