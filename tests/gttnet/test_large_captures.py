"""Long and order-free captures: pose-order windows without sequencing, and running out of memory as one line."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.capture.views import make_view
from gttnet.cli import main as gttnet_main
from gttnet.windowed import pose_times, reconstruct_windowed


@pytest.fixture(scope="module")
def scene():
    from tests.fixtures.scenes import make_scene

    return make_scene(n_cameras=4, n_joints=8, frames_per_camera=40, sigma_px=1.0, missing=0.05, seed=3)


@pytest.fixture(scope="module")
def shard(scene, tmp_path_factory):
    from gttdata.shards.writer import ShardWriter

    d = tmp_path_factory.mktemp("large")
    with ShardWriter(d / "shards", split="test") as w:
        w.write(scene)
    return sorted((d / "shards").glob("*.h5"))[0]


def test_pose_times_follow_time_without_sequencing(scene):
    obs, gt = make_view(scene, "none")
    t = pose_times(obs)
    assert t.shape == (obs.n_images,) and sorted(t.tolist()) == list(range(obs.n_images))
    from gttnet.evaluate.metrics import kendall_tau

    # a smooth motion: the poses' own order follows time closely (up to direction)
    assert kendall_tau(t.astype(np.int64), np.argsort(np.argsort(gt.timestamp_s))) > 0.6


def test_windowed_without_sequencing_close_to_whole(scene):
    obs, gt = make_view(scene, "none")
    whole = reconstruct_windowed(obs, "dloe", window="auto")  # 160 images: one piece
    assert "windows" not in whole.info
    win = reconstruct_windowed(obs, "dloe", window=60)
    assert win.info["windows"] >= 3 and win.info["clock"] == "pose order"
    assert sorted(win.order.tolist()) == list(range(obs.n_images))

    def err(rec):
        return float(np.nanmean(np.linalg.norm(rec.points3d - gt.points3d, axis=-1)))

    assert err(win) < 1.5 * err(whole), (err(win), err(whole))


@pytest.mark.parametrize(
    "exc",
    [MemoryError("Unable to allocate 4.29 GiB for an array with shape (24000, 24000)"),
     RuntimeError("[enforce fail at alloc_cpu.cpp:117] DefaultCPUAllocator: can't allocate memory")],
)  # fmt: skip
def test_out_of_memory_is_one_line(shard, monkeypatch, exc):
    import gttnet.methods

    def boom(*args, **kwargs):
        raise exc

    monkeypatch.setattr(gttnet.methods, "reconstruct", boom)
    res = CliRunner().invoke(gttnet_main, ["reconstruct", str(shard), "--method", "pseudo", "--quiet"])
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: out of memory"), res.output
    assert "Traceback" not in res.output


def test_other_runtime_errors_still_raise(shard, monkeypatch):
    import gttnet.methods

    def boom(*args, **kwargs):
        raise RuntimeError("something else")

    monkeypatch.setattr(gttnet.methods, "reconstruct", boom)
    res = CliRunner().invoke(gttnet_main, ["reconstruct", str(shard), "--method", "pseudo", "--quiet"])
    assert res.exit_code == 1 and isinstance(res.exception, RuntimeError)
