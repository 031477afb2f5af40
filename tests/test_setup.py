"""The fresh-machine set-up: the Makefile picks (or makes) a virtualenv, installs pinned versions, CI starts clean.

``make -n`` prints what a target would run without running it, so these tests check the interpreter and the
pip command each environment gets in a fraction of a second. The real thing (a fresh clone, a fresh ``.venv``,
``make test``) takes minutes and is what ``.ci/run`` does.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CONSTRAINTS = ROOT / "constraints.txt"

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


def _dry_run(target: str, env: dict[str, str], *args: str) -> list[str]:
    res = subprocess.run(
        ["make", "-n", "-C", str(ROOT), target, *args], capture_output=True, text=True, env=env, timeout=60
    )
    assert res.returncode == 0, res.stderr
    return [ln for ln in res.stdout.splitlines() if ln.strip() and not ln.startswith("make")]


def _base_env(python_dir: str) -> dict[str, str]:
    """An environment whose ``python3`` is the one in ``python_dir`` and where no virtualenv is active."""
    # Under `make test` the environment carries make's own variables (MAKEFLAGS holds PYTHON=... from .ci/run's
    # command line): a nested make would inherit them.
    drop = (
        "VIRTUAL_ENV",
        "MAKEFLAGS",
        "MFLAGS",
        "MAKELEVEL",
        "MAKEOVERRIDES",
        "PYTHON",
        "VENV",
        "BASE_PYTHON",
    )
    env = {k: v for k, v in os.environ.items() if k not in drop}
    env["PATH"] = os.pathsep.join([python_dir, "/usr/bin", "/bin"])
    return env


def _system_python(tmp_path: Path) -> str:
    """A folder whose ``python3`` runs outside any virtualenv (the base interpreter of this one)."""
    base = Path(sys.base_prefix) / "bin" / "python3"
    if not base.exists():
        pytest.skip(f"no base interpreter at {base}")
    (tmp_path / "python3").symlink_to(base)
    return str(tmp_path)


def _pins() -> dict[str, str]:
    pins = {}
    for line in CONSTRAINTS.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, version = line.split("==")
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    return pins


def test_outside_a_virtualenv_make_creates_and_uses_dot_venv(tmp_path):
    venv = tmp_path / "venv"  # VENV (default .venv) not made yet, whether or not this checkout has a .venv
    lines = _dry_run("test", _base_env(_system_python(tmp_path)), f"VENV={venv}")
    assert lines[0] == f"bash scripts/make_venv.sh python3 {venv}"
    assert all(ln.startswith(f"{venv}/bin/python") for ln in lines if "python" in ln.split()[0]), lines
    assert (
        f'{venv}/bin/python -m pip install -q -c constraints.txt -e ".[train,preview,dev,formats]"' in lines
    )
    assert "/.venv/" in (ROOT / ".gitignore").read_text().split()


def test_inside_a_virtualenv_make_uses_it(tmp_path):
    venv_bin = str(Path(sys.executable).parent)
    if sys.prefix == sys.base_prefix:
        pytest.skip("the tests do not run in a virtualenv")
    env = _base_env(venv_bin)
    lines = _dry_run("install", env)  # python3 on the PATH is a virtualenv's (sys.prefix != sys.base_prefix)
    assert lines == ['python3 -m pip install -q -c constraints.txt -e ".[train,preview,dev,formats]"'], lines
    env = {**_base_env(_system_python(tmp_path)), "VIRTUAL_ENV": "/opt/some-venv"}  # activated, by variable
    assert _dry_run("install", env)[0].startswith(
        "/opt/some-venv/bin/python -m pip install -q -c constraints"
    )


def test_ci_starts_from_a_fresh_virtualenv_and_runs_the_readme_command():
    ci = (ROOT / ".ci" / "run").read_text()
    assert "rm -rf .venv" in ci and re.search(r"^make test PYTHON=\.venv/bin/python$", ci, re.M)
    assert ci.index("rm -rf .venv") < ci.index("make test")
    assert "make test" in (ROOT / "README.md").read_text()


def test_constraints_pin_everything_pyproject_asks_for():
    """Every dependency of gtt and of the installed extras is pinned once, inside pyproject's own ranges."""
    from packaging.requirements import Requirement

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = re.search(r"^EXTRAS := (\S+)$", (ROOT / "Makefile").read_text(), re.M).group(1).split(",")
    pins = _pins()
    assert "gtt" not in pins, "constraints.txt must not pin the project itself"
    assert pins.get("torch") == "2.13.0"
    wanted = [*project["dependencies"], *(r for e in extras for r in project["optional-dependencies"][e])]
    for text in wanted:
        req = Requirement(text)
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        assert name in pins, f"constraints.txt: {req.name} is not pinned (run make lock)"
        assert req.specifier.contains(pins[name], prereleases=True), (
            f"constraints.txt: {req.name}=={pins[name]} is outside pyproject.toml's {req.specifier}"
        )
    lines = [ln for ln in CONSTRAINTS.read_text().splitlines() if ln and not ln.startswith("#")]
    assert len(lines) == len(pins), "a package is pinned twice"


def test_constraints_agree_with_the_machines_pip_constraints():
    """Pip applies the machine's global constraints as well: a pin outside them would make install fail."""
    from packaging.requirements import Requirement

    machine = Path("/etc/xdg/pip/constraints.txt")
    if not machine.exists():
        pytest.skip("no machine-wide pip constraints here")
    pins = _pins()
    for line in machine.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            req = Requirement(line)
            pin = pins.get(re.sub(r"[-_.]+", "-", req.name).lower())
            assert pin is None or req.specifier.contains(pin), (
                f"constraints.txt pins {req.name}=={pin}; {line}"
            )
