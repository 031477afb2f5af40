"""Every command of both CLIs follows docs/CLI.md where a machine can check it.

Walks every (sub)command of ``gttdata`` and ``gttnet`` and checks its ``--help`` and options: an
``Examples:`` block of runnable-looking command lines, ``--out`` for output (never ``--dest``/``--output``),
``--progress`` with ``--quiet``, ``--resume`` with ``--overwrite``, ``--split`` (default ``test``) with
``--sample``, ``--method`` as a checked choice of registered methods, ``--json`` as a plain flag, and
every ``--units`` defaulting to metres (or to "not given": the file's own unit, else metres with a warning).
"""

from __future__ import annotations

import re

import click
import pytest
from click.testing import CliRunner

from gttdata.cli import main as gttdata_main
from gttnet.cli import main as gttnet_main

#: Commands that run long enough for a progress bar: they take --progress/--no-progress and --quiet.
LONG = {"gttdata generate", "gttdata preview", "gttnet evaluate", "gttnet train", "gttnet reconstruct"}


def _walk(group: click.Group, prefix: list[str]):
    ctx = click.Context(group)
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if isinstance(cmd, click.Group):
            yield " ".join([*prefix, name]), cmd
            yield from _walk(cmd, [*prefix, name])
        else:
            yield " ".join([*prefix, name]), cmd


COMMANDS = dict(_walk(gttdata_main, ["gttdata"])) | dict(_walk(gttnet_main, ["gttnet"]))


def _opts(cmd: click.Command) -> dict[str, click.Option]:
    out = {}
    for p in cmd.params:
        if isinstance(p, click.Option):
            for name in p.opts + p.secondary_opts:
                out[name] = p
    return out


def test_walk_finds_every_command():
    assert {"gttdata generate", "gttdata inspect", "gttdata motions fetch", "gttnet reconstruct"} <= set(
        COMMANDS
    )
    assert len(COMMANDS) >= 15


@pytest.mark.parametrize("path", sorted(COMMANDS))
def test_help_has_examples(path):
    root = gttdata_main if path.startswith("gttdata") else gttnet_main
    res = CliRunner().invoke(root, [*path.split()[1:], "--help"], terminal_width=200)
    assert res.exit_code == 0, res.output
    block = re.search(r"^[ \t]*Examples:\n((?:[ \t]+\S.*\n)+)", res.output, re.M)
    assert block, f"{path} --help has no 'Examples:' block (docs/CLI.md):\n{res.output}"
    lines = [ln.strip() for ln in block.group(1).splitlines() if ln.strip()]
    assert lines and all(ln.startswith(path.split()[0] + " ") for ln in lines), lines
    assert any(ln.startswith(path + " ") or ln == path for ln in lines), (
        f"{path}: no example of itself: {lines}"
    )


@pytest.mark.parametrize("path", sorted(p for p, c in COMMANDS.items() if not isinstance(c, click.Group)))
def test_options_follow_the_convention(path):
    cmd = COMMANDS[path]
    opts = _opts(cmd)
    primary = {p.opts[0] for p in cmd.params if isinstance(p, click.Option)}
    bad = primary & {"--dest", "--output", "--output-dir", "--out-dir", "--outdir", "--no-resume"}
    assert not bad, f"{path}: {sorted(bad)}; docs/CLI.md names them --out / --resume"
    if "--out" in opts:
        assert opts["--out"].help, f"{path}: --out has no help text"
    if path in LONG:
        assert "--progress" in opts and "--no-progress" in opts and "--quiet" in opts, path
        assert opts["--quiet"].is_flag
    if "--quiet" in opts or "--progress" in opts:
        assert "--quiet" in opts and "--progress" in opts, f"{path}: --progress and --quiet come together"
    if "--resume" in opts or "--overwrite" in opts:
        assert "--overwrite" in opts, f"{path}: --resume without --overwrite"
        if "--resume" in opts:  # a flag (train also takes a run folder after it, as a shorthand)
            r = opts["--resume"]
            assert r.is_flag or r.flag_value is not None, path
    if "--split" in opts:
        assert opts["--split"].default == "test", f"{path}: --split defaults to {opts['--split'].default!r}"
        assert "--sample" in opts, f"{path}: --split without --sample"
    if "--method" in opts:
        from gttnet.methods import available_methods

        t = opts["--method"].type
        assert isinstance(t, click.Choice), f"{path}: --method is free text"
        assert set(t.choices) <= set(available_methods()), (path, t.choices)
    if "--json" in opts:
        assert opts["--json"].is_flag, path
    if "--units" in opts:  # readers and writers alike: metres unless told (docs/CLI.md, "Units")
        assert opts["--units"].default in (None, "m"), (
            f"{path}: --units defaults to {opts['--units'].default!r}"
        )


def test_method_choices_are_registered_methods():
    """In a fresh interpreter: other tests register throw-away methods in this process's registry."""
    import json
    import subprocess
    import sys

    from gttnet.cli._options import AFFINITY_METHODS

    code = "import json; from gttnet.methods import available_methods as a; print(json.dumps(sorted(a())))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    registered = set(json.loads(out.strip().splitlines()[-1]))
    assert set(AFFINITY_METHODS) <= registered
    reconstruct = _opts(COMMANDS["gttnet reconstruct"])["--method"].type
    assert set(reconstruct.choices) == registered


def test_format_choices_are_the_importers_formats():
    from gttnet.cli._options import INPUT_FORMATS
    from gttnet.io import FORMATS

    assert INPUT_FORMATS == ("auto", *FORMATS)
    for name in ("gttnet reconstruct", "gttnet sync"):
        assert tuple(_opts(COMMANDS[name])["--format"].type.choices) == INPUT_FORMATS
