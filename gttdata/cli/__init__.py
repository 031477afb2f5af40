"""The ``gttdata`` command group; each subcommand lives in its own module."""

from __future__ import annotations

import functools
import importlib.metadata as md

import click

from gttdata.errors import GttDataError
from gttdata.fileio import describe_os_error

__all__ = ["main", "friendly_errors"]


def _versions() -> str:
    names = ("gtt", "numpy", "scipy", "h5py", "opencv-python-headless", "click", "pyyaml")
    out = []
    for n in names:
        try:
            out.append(f"{n} {md.version(n)}")
        except md.PackageNotFoundError:
            out.append(f"{n} (not installed)")
    return ", ".join(out)


def friendly_errors(fn):
    """Decorator: turn library errors (and common OS errors) into one readable ClickException line."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except GttDataError as exc:
            raise click.ClickException(str(exc)) from exc
        except (FileNotFoundError, PermissionError, IsADirectoryError) as exc:
            raise click.ClickException(f"{exc.filename}: {exc.strerror}") from exc
        except OSError as exc:  # ENOSPC, EROFS...: one line naming the path
            reason = describe_os_error(exc)
            raise click.ClickException(f"{exc.filename}: {reason}" if exc.filename else reason) from exc

    return wrapper


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="gtt", message=f"gttdata %(version)s ({_versions()})")
def main() -> None:
    """Simulate unsynchronized multi-camera captures from mocap and write them as HDF5 shards."""


def _register() -> None:
    """Attach subcommands; each module adds itself to ``main``. Missing modules are skipped."""
    for mod in ("motions", "generate", "inspect", "verify", "preview", "export"):
        try:
            importlib_module = __import__(f"gttdata.cli.{mod}", fromlist=["register"])
        except ModuleNotFoundError as exc:
            if exc.name != f"gttdata.cli.{mod}":
                raise
            continue
        importlib_module.register(main)


_register()
