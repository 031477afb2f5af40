"""Pieces shared by the ``gttdata`` and ``gttnet`` command groups (click only: both CLIs import it at start-up).

Both groups follow docs/CLI.md; what is written once here is the ``--version`` option and the options that
pick one sample of a stored capture (``--sample``/``--split``/``--variant``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import click

__all__ = ["SPLIT_DEFAULT", "sample_options", "version_option"]

F = TypeVar("F", bound=Callable[..., Any])

#: Default ``--split`` of every command that reads a dataset folder.
SPLIT_DEFAULT = "test"


def _versions(packages: Sequence[str]) -> str:
    import importlib.metadata as md  # metadata lookups cost tens of ms: only on --version

    out = []
    for name in packages:
        try:
            out.append(f"{name} {md.version(name)}")
        except md.PackageNotFoundError:
            out.append(f"{name} (not installed)")
    return ", ".join(out)


def version_option(prog: str, packages: Sequence[str]) -> Callable[[F], F]:
    """Return an eager ``--version`` flag that prints ``prog`` and the versions of ``packages``, then exits.

    Args:
        prog: Command name printed first, e.g. ``"gttdata"``.
        packages: Distribution names whose installed versions are listed.
    """

    def _print(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
        if not value or ctx.resilient_parsing:
            return
        click.echo(f"{prog} {_versions(packages)}")
        ctx.exit()

    return click.option(
        "--version",
        is_flag=True,
        expose_value=False,
        is_eager=True,
        callback=_print,
        help="Show the versions of gtt and its main dependencies, then exit.",
    )


def sample_options(
    sample_help: str, split_help: str, variant_help: str = "Input variant stored in a shard."
) -> Callable[[F], F]:
    """Return the ``--sample``/``--split``/``--variant`` options that pick one stored capture.

    Args:
        sample_help: Help text of ``--sample``.
        split_help: Help text of ``--split`` (its default is :data:`SPLIT_DEFAULT` everywhere).
        variant_help: Help text of ``--variant``.
    """

    def decorate(f: F) -> F:
        f = click.option("--variant", default="orig", show_default=True, help=variant_help)(f)
        f = click.option("--split", default=SPLIT_DEFAULT, show_default=True, help=split_help)(f)
        return click.option(
            "--sample", "-s", type=click.IntRange(min=0), default=0, show_default=True, help=sample_help
        )(f)

    return decorate
