"""Item 6: recipe sanity bounds (refused, one line, before any work) and unusable samples refused."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from gttdata.cli import main
from tests.reliability.conftest import TINY, one_line_error


@pytest.mark.parametrize(
    ("override", "key"),
    [
        ("splits.0.n_samples=1000000000000", "n_samples"),
        ("capture.fps_hz=10000000", "fps_hz"),
        ("rig.n_cameras=1", "n_cameras"),
        ("capture.joint_drop_rate=1.0", "joint_drop_rate"),
        ("capture.fps_hz=9000 capture.window_s=10", "images per sample"),
    ],
)
def test_absurd_or_unusable_recipe_is_refused_before_work(tmp_path, override, key):
    out = tmp_path / "d"
    line = one_line_error(
        CliRunner().invoke(main, ["generate", TINY, *override.split(), "--out", str(out), "--no-progress"])
    )
    assert key in line and "expected" in line
    assert not out.exists(), "nothing is written for a refused recipe"


def test_one_frame_capture_is_refused_not_written(tmp_path):
    """A window shorter than one frame gave 0-image samples and exit 0."""
    out = tmp_path / "d"
    res = CliRunner().invoke(
        main, ["generate", TINY, "capture.window_s=0.01", "--out", str(out), "--no-progress"]
    )
    line = one_line_error(res)
    assert "at least 2 cameras" in line and "sample 0" in line
    assert not list(out.glob("*/shard-*.h5"))


def test_one_frame_motion_file_is_refused_not_written(tmp_path):
    """Reproduction of item 6: a 1-frame motion file exited 0 with a dataset no solver can use."""
    from gttdata.mocap.arrays import save_motion
    from gttdata.mocap.procedural import generate_motion

    walk = generate_motion("walk", seed=0, duration_s=1.0)
    one = type(walk)(positions=walk.positions[:1], fps_hz=walk.fps_hz, skeleton=walk.skeleton, name="one")
    motion = save_motion(one, tmp_path / "one.npz")
    recipe = tmp_path / "r.yaml"
    recipe.write_text(
        f"name: one\nsplits:\n  - name: test\n    n_samples: 1\n    sources: [{{kind: files, paths: [{motion}]}}]\n"
        "rig: {kind: ring, n_cameras: 3}\ncapture: {window_s: 0.5, fps_hz: 10}\n"
    )
    out = tmp_path / "d"
    line = one_line_error(
        CliRunner().invoke(main, ["generate", str(recipe), "--out", str(out), "--no-progress"])
    )
    assert "at least 2 cameras" in line and "one" in line
    assert not list(out.glob("*/shard-*.h5"))
