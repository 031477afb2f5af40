"""Pieces shared by the ``gttdata`` and ``gttnet`` command groups (click only: both CLIs import it at start-up).

Both groups follow docs/CLI.md; what is written once here is the ``--version`` option and the options that
pick one sample of a stored capture (``--sample``/``--split``/``--variant``).
"""

from __future__ import annotations

import contextlib
import logging
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import click
from click.core import ParameterSource

__all__ = [
    "SPLIT_DEFAULT",
    "WarningLines",
    "check_shard_split",
    "install_warning_lines",
    "not_a_warning_line",
    "prints_warnings",
    "sample_options",
    "version_option",
    "warning_lines",
]

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


def check_shard_split(path: str | Path, split: str | None) -> None:
    """Refuse a ``--split`` the user gave that contradicts the own split of a shard file ``path``.

    A shard file holds one split, so ``--split`` cannot select anything in it; its default (``test``)
    is ignored there, but a split typed on the command line that differs from the shard's is a
    mistake worth one line rather than a silent read of another split. Not a shard file (a folder, a
    recipe, another format, an unreadable file): nothing to check here, the command's reader reports.

    Raises:
        click.ClickException: ``--split`` given explicitly and different from the shard's ``split``.
    """
    ctx = click.get_current_context(silent=True)
    if split is None or ctx is None:
        return
    if ctx.get_parameter_source("split") in (None, ParameterSource.DEFAULT, ParameterSource.DEFAULT_MAP):
        return
    p = Path(path)
    if not p.is_file() or p.suffix.lower() not in (".h5", ".hdf5"):
        return
    from gttdata.errors import ShardFormatError  # light, but keep start-up free of h5py
    from gttdata.shards.reader import ShardReader

    try:
        with ShardReader(p) as reader:
            own = reader.attrs.get("split")
    except ShardFormatError:
        return
    if own is not None and own != split:
        raise click.ClickException(
            f"{p}: --split {split!r} contradicts the shard's own split {own!r}; a shard file holds one "
            f"split (drop --split, or pass --split {own})"
        )


class WarningLines(logging.Handler):
    """Echo a library logger's warnings as ``warning: ...`` lines on stderr (docs/CLI.md)."""

    def emit(self, record: logging.LogRecord) -> None:
        """Print the record as one ``warning:`` line, once however many of these handlers it reaches.

        A logger silenced with a ``NullHandler`` stays silent (gttnet.sync: its commands print those
        warnings themselves, by camera name).
        """
        if getattr(record, "_gtt_warning_line", False):
            return
        lg: logging.Logger | None = logging.getLogger(record.name)
        while lg is not None and not any(h is self for h in lg.handlers):
            if any(isinstance(h, logging.NullHandler) for h in lg.handlers):
                return
            lg = lg.parent if lg.propagate else None
        record._gtt_warning_line = True
        click.echo(f"warning: {record.getMessage()}", err=True)


@contextlib.contextmanager
def warning_lines(*names: str) -> Iterator[None]:
    """Inside the block, warnings logged under the loggers ``names`` (default: all of gttdata) print as ``warning:`` lines.

    A logger whose warnings already print (:func:`install_warning_lines`) gets no second handler.
    """
    handler = WarningLines(logging.WARNING)
    loggers = [logging.getLogger(n) for n in (names or ("gttdata",))]
    loggers = [lg for lg in loggers if not prints_warnings(lg)]
    for lg in loggers:
        lg.addHandler(handler)
    try:
        yield
    finally:
        for lg in loggers:
            lg.removeHandler(handler)


def prints_warnings(logger: logging.Logger) -> bool:
    """Whether ``logger``'s warnings already reach a :class:`WarningLines` handler (its own or an ancestor's)."""
    lg: logging.Logger | None = logger
    while lg is not None:
        if any(isinstance(h, WarningLines) for h in lg.handlers):
            return True
        lg = lg.parent if lg.propagate else None
    return False


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    click.echo(f"warning: {message}", err=True)


def install_warning_lines() -> None:
    """Make every warning a command prints one ``warning: ...`` line on stderr (docs/CLI.md).

    Python warnings (``warnings.warn``) lose their ``file:line: Category:`` prefix and source line, and
    the gttdata and gttnet loggers' warnings print as ``warning:`` lines (a command that also logs to the
    root logger, as ``gttnet train`` does, filters them there). Called by both command groups.
    """
    warnings.showwarning = _show_warning
    for name in ("gttdata", "gttnet"):
        lg = logging.getLogger(name)
        if not any(isinstance(h, WarningLines) for h in lg.handlers):
            lg.addHandler(WarningLines(logging.WARNING))


def not_a_warning_line(record: logging.LogRecord) -> bool:
    """Logging filter: False for the gttdata/gttnet warnings :func:`install_warning_lines` already prints."""
    return not (record.levelno >= logging.WARNING and record.name.split(".")[0] in ("gttdata", "gttnet"))
