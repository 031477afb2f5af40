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


def _commands(package: str) -> list[list[str]]:
    from importlib import import_module

    import click

    def walk(group: click.Group, prefix: list[str]):
        for name, cmd in group.commands.items():
            if isinstance(cmd, click.Group):
                yield from walk(cmd, [*prefix, name])
            else:
                yield [*prefix, name]

    return list(walk(import_module(f"{package}.cli").main, []))


@pytest.mark.parametrize("package", ["gttnet", "gttdata"])
def test_every_command_help_loads_no_heavy_library(package):
    """``--help`` of every subcommand, each in a fresh interpreter, loads neither torch nor numpy and the rest."""
    commands = _commands(package)
    assert len(commands) >= 5
    statement = (
        f"from {package}.cli import main\n"
        f"for args in {commands!r}:\n"
        "    try:\n        main([*args, '--help'], standalone_mode=False)\n    except SystemExit:\n        pass"
    )
    assert _loaded_after(statement) == []


@pytest.fixture(scope="module")
def tiny_shard(tmp_path_factory):
    from gttdata.shards.writer import ShardWriter
    from tests.fixtures.scenes import make_scene

    sample = make_scene(n_cameras=3, n_joints=6, frames_per_camera=10, sigma_px=1.0, missing=0.1, seed=5)
    d = tmp_path_factory.mktemp("startup")
    with ShardWriter(d / "shards", split="test") as w:
        w.write(sample)
    return sorted((d / "shards").glob("*.h5"))[0]


CLASSICAL = [("dloe", "none"), ("dloe", "partial"), ("pseudo", "none"), ("hpf", "full"), ("dct", "full"),
             ("sync", "partial"), ("auto", "partial"), ("auto", "full")]  # fmt: skip


@pytest.mark.parametrize(("method", "sequencing"), CLASSICAL)
def test_classical_reconstruct_never_imports_torch(tiny_shard, method, sequencing):
    """A whole ``gttnet reconstruct`` run of a classical method, in a fresh interpreter, leaves torch unloaded."""
    args = ["reconstruct", str(tiny_shard), "--method", method, "--sequencing", sequencing, "--json"]
    statement = (
        "from gttnet.cli import main\n"
        f"try:\n    main({args!r}, standalone_mode=False)\nexcept SystemExit as e:\n    assert not e.code, e\n"
        "assert 'gttnet.baselines.dloe' in sys.modules or 'gttnet.baselines.highpass' in sys.modules or "
        "'gttnet.baselines.pseudo' in sys.modules or 'gttnet.baselines.trajectory_basis' in sys.modules"
    )
    loaded = _loaded_after(statement)
    assert "torch" not in loaded, loaded
    assert not {"cv2", "matplotlib", "yaml", "tqdm", "trimesh", "pyrender"} & set(loaded), loaded


def test_torch_probe_can_fail(tiny_shard):
    """The same probe sees torch when the method needs it (GTT-Net)."""
    from gttnet.model.inference import BUNDLED_MODEL

    if not BUNDLED_MODEL.is_file():
        pytest.skip("no bundled model")
    args = ["reconstruct", str(tiny_shard), "--method", "gttnet", "--sequencing", "partial", "--json"]
    statement = f"from gttnet.cli import main\ntry:\n    main({args!r}, standalone_mode=False)\nexcept SystemExit:\n    pass"
    assert "torch" in _loaded_after(statement)


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
