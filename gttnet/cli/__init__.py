"""The ``gttnet`` command group; each subcommand lives in its own module."""

from __future__ import annotations

import importlib.metadata as md

import click

__all__ = ["main"]


def _versions() -> str:
    out = []
    for n in ("gtt", "torch", "numpy", "scipy"):
        try:
            out.append(f"{n} {md.version(n)}")
        except md.PackageNotFoundError:
            out.append(f"{n} (not installed)")
    return ", ".join(out)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="gtt", message=f"gttnet %(version)s ({_versions()})")
def main() -> None:
    """Reconstruct dynamic 3D skeletons from unsynchronized multi-camera 2-D observations."""


def _register() -> None:
    """Attach subcommands; each module adds itself to ``main``. Missing modules are skipped."""
    for mod in ("reconstruct", "sync", "train", "evaluate", "segment", "render"):
        try:
            module = __import__(f"gttnet.cli.{mod}", fromlist=["register"])
        except ModuleNotFoundError as exc:
            if exc.name != f"gttnet.cli.{mod}":
                raise
            continue
        module.register(main)


_register()
