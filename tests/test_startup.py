"""The CLIs start at once: importing their command groups loads none of the heavy libraries.

Each check runs in a fresh interpreter, since this test process has long imported torch and numpy.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
from click.testing import CliRunner

from tests._subprocess import repo_env

HEAVY = ("torch", "numpy", "scipy", "cv2", "h5py", "matplotlib", "yaml", "tqdm", "trimesh", "pyrender")


def _loaded_after(statement: str) -> list[str]:
    code = (
        f"import json, sys\n{statement}\nprint(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=repo_env(), check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("package", ["gttnet", "gttdata"])
def test_cli_import_loads_no_heavy_library(package):
    assert _loaded_after(f"import {package}.cli") == []


@pytest.mark.parametrize("package", ["gttnet", "gttdata"])
def test_help_loads_no_heavy_library(package):
    statement = (
        f"from {package}.cli import main\n"
        "try:\n    main(['--help'], standalone_mode=False)\nexcept SystemExit:\n    pass"
    )
    assert _loaded_after(statement) == []


def test_package_import_is_lazy_but_complete():
    """``import gttdata`` loads nothing heavy, yet its public names still resolve."""
    assert _loaded_after("import gttdata") == []
    import gttdata

    for name in gttdata.__all__:
        assert getattr(gttdata, name) is not None


def test_heavy_check_can_fail():
    """The subprocess probe does see a heavy import when one happens."""
    assert _loaded_after("import gttdata.cameras") != []


@pytest.mark.parametrize("package", ["gttnet", "gttdata"])
def test_version_names_the_dependencies(package):
    from importlib import import_module

    result = CliRunner().invoke(import_module(f"{package}.cli").main, ["--version"])
    assert result.exit_code == 0, result.output
    assert result.output.startswith(f"{package} gtt ") and "numpy" in result.output
