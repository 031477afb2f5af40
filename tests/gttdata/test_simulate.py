"""Capture simulation: geometry is exact, noise and missing rates match their parameters, events stay apart.

The subject is the synthetic body of ``tests.fixtures.scenes`` (31 joints within ~0.5 m of the origin,
0.1-1.7 m high) sampled at 120 Hz into a Motion; a 4-camera ring 3 m away sees all of it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.csgraph import connected_components

from gttdata.cameras import Camera, CameraRig, look_at, ring_rig
from gttdata.capture.occlusion import drop_images, visible_in_camera
from gttdata.capture.simulate import CaptureParams, merge_subjects, simulate_capture, simulate_events
from gttdata.capture.timing import min_cross_camera_gap
from gttdata.mocap.motion import Motion
from gttdata.skeleton import cmu31
from tests.fixtures.scenes import body_positions


def _motion(duration_s: float = 3.0, seed: int = 0, name: str = "body") -> Motion:
    t = np.arange(int(duration_s * 120) + 1) / 120.0
    return Motion(body_positions(t, 31, seed=seed), 120.0, cmu31(), name=f"{name}{seed}")


def _params(v: int = 4, **kw) -> CaptureParams:
    base = {"fps_hz": (30.0,) * v, "duration_s": 2.5, "drift_ppm": (0.0,) * v}
    return CaptureParams(**{**base, **kw})


def _simulate(seed: int = 0, rig: CameraRig | None = None, **kw):
    rig = ring_rig(4, radius_m=3.0, height_m=1.2) if rig is None else rig
    return simulate_capture(_motion(), rig, _params(len(rig), **kw), np.random.default_rng(seed), name="s")


def test_geometry_and_bookkeeping():
    s = _simulate(sigma_px=0.0)
    motion = _motion()
    assert s.n_images == 300 and s.n_cameras == 4 and s.n_joints == 31
    assert np.all(np.diff(s.timestamp_s) > 0)
    assert np.array_equal(s.global_order, np.arange(300))
    assert min_cross_camera_gap(s.timestamp_s, s.cam_id) > 0
    np.testing.assert_allclose(s.points3d, motion.sample_at(s.timestamp_s), atol=1e-12)
    for n in range(s.n_images):
        cam = Camera(s.K[n], s.cam_from_world[n])
        px, depth = cam.project(s.points3d[n])
        np.testing.assert_allclose(s.keypoints_gt_px[n], px, atol=1e-3)
        assert np.all(depth > 0)
    assert s.visible.all()
    np.testing.assert_allclose(s.keypoints_px, s.keypoints_gt_px, atol=1e-3)
    for v in range(4):
        assert np.array_equal(s.stream_index[s.cam_id == v], np.arange(75))
    assert s.meta["capture"]["sigma_px"] == 0.0 and len(s.meta["offsets_s"]) == 4
    # Ground-truth neighbours are the adjacent images (other cameras in an even interleave).
    assert np.array_equal(s.affinity_nbr[1:-1, 0], np.arange(0, 298))


def test_noise_sigma_matches_parameter():
    sigma = 3.0
    s = _simulate(seed=1, sigma_px=sigma)
    r = (s.keypoints_px - s.keypoints_gt_px)[s.visible].astype(np.float64).ravel()
    n = r.size
    assert n > 10000
    se = sigma / np.sqrt(2 * (n - 1))  # standard error of a sample std of Gaussian data
    assert abs(r.std() - sigma) < 5 * se
    assert abs(r.mean()) < 5 * sigma / np.sqrt(n)


def test_outlier_rate_matches_parameter():
    s = _simulate(seed=2, sigma_px=1.0, outlier_rate=0.1, outlier_sigma_px=200.0)
    n = int(s.visible.sum())
    rate = s.meta["n_outliers"] / n
    assert abs(rate - 0.1) < 5 * np.sqrt(0.1 * 0.9 / n)
    big = np.abs(s.keypoints_px - s.keypoints_gt_px)[s.visible].max(axis=-1) > 10
    assert abs(big.mean() - 0.1) < 0.02


@pytest.mark.parametrize("rate", [0.1, 0.3, 0.5])
def test_joint_drop_rate_matches_parameter(rate: float):
    s = _simulate(seed=3, joint_drop_rate=rate)
    in_view = visible_in_camera(
        s.keypoints_gt_px.astype(np.float64), np.ones(s.visible.shape), s.image_size[s.cam_id]
    )
    n = int(in_view.sum())
    dropped = 1.0 - s.visible[in_view].mean()
    assert abs(dropped - rate) < 5 * np.sqrt(rate * (1 - rate) / n)
    assert np.all(np.isnan(s.keypoints_px[~s.visible]))
    assert not np.any(np.isnan(s.keypoints_px[s.visible]))
    assert s.meta["missing_rate"] == pytest.approx(1.0 - s.visible.mean())


def test_image_drop_rate_matches_parameter():
    rate = 0.2
    counts = [_simulate(seed=10 + k, image_drop_rate=rate).n_images for k in range(10)]
    kept = np.sum(counts) / (300 * len(counts))
    assert abs((1 - kept) - rate) < 5 * np.sqrt(rate * (1 - rate) / (300 * len(counts)))
    keep = drop_images(np.repeat(np.arange(3), 4), np.random.default_rng(0), rate=0.99)
    assert all(keep[v * 4 : v * 4 + 4].sum() >= 2 for v in range(3))


def test_behind_camera_and_outside_image_are_missing():
    front = look_at(np.array([3.0, 0.0, 1.0]), np.array([0.0, 0.0, 0.9]))
    back = look_at(np.array([3.0, 0.0, 1.0]), np.array([6.0, 0.0, 0.9]))
    narrow = Camera(np.array([[1000.0, 0, 150], [0, 1000, 150], [0, 0, 1]]), front, (300, 300))
    K = np.array([[1000.0, 0, 500], [0, 1000, 500], [0, 0, 1]])
    rig = CameraRig((Camera(K, front), Camera(K, back), narrow))
    s = simulate_capture(_motion(), rig, _params(3), np.random.default_rng(0), name="s")
    assert s.visible[s.cam_id == 0].all()
    assert not s.visible[s.cam_id == 1].any()
    assert np.all(np.isnan(s.keypoints_gt_px[s.cam_id == 1]))
    part = s.visible[s.cam_id == 2]
    assert 0 < part.mean() < 1


def test_events_are_disjoint_in_time_and_affinity():
    motions = [_motion(seed=k) for k in range(3)]
    params = _params(duration_s=1.0)
    s = simulate_events(motions, ring_rig(4), params, np.random.default_rng(0), gaps_s=[0.5, 0.8], name="ev")
    event = np.asarray(s.meta["event_id"])
    starts = np.asarray(s.meta["event_start_s"])
    np.testing.assert_allclose(starts, [0.0, 1.5, 3.3])
    assert event.shape == (s.n_images,) and set(event.tolist()) == {0, 1, 2}
    local = s.timestamp_s - starts[event]
    assert np.all((local >= 0) & (local < 1.0))
    for e in range(3):
        np.testing.assert_allclose(
            s.points3d[event == e], motions[e].sample_at(local[event == e]), atol=1e-12
        )
    nbr = s.affinity_nbr
    ok = nbr >= 0
    assert np.all(event[np.nonzero(ok)[0]] == event[nbr[ok]])
    n_comp, labels = connected_components(s.affinity_binary(), directed=False)
    assert n_comp == 3
    assert all(len(set(labels[event == e])) == 1 for e in range(3))


def test_merge_subjects_stacks_skeletons():
    a, b = _motion(seed=0), _motion(seed=1)
    m = merge_subjects([a, b], np.array([[-1.0, 0, 0], [1.0, 0, 0]]))
    assert m.skeleton.n_joints == 62
    assert m.skeleton.joint_names[0] == "a_root" and m.skeleton.joint_names[31] == "b_root"
    assert m.skeleton.parents[32] == 31
    np.testing.assert_allclose(m.positions[:, 31:], b.positions + [1.0, 0, 0])
    assert m.skeleton.joint_names[m.skeleton.mirror[33]] == "b_rfemur"


def test_simulation_is_deterministic_given_rng():
    kw = {"sigma_px": 2.0, "joint_drop_rate": 0.2, "jitter_s": 1e-3, "image_drop_rate": 0.1}
    a, b = _simulate(seed=5, **kw), _simulate(seed=5, **kw)
    for f in ("timestamp_s", "cam_id", "keypoints_px", "visible", "points3d", "affinity_w"):
        assert np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
    c = _simulate(seed=6, **kw)
    assert not np.array_equal(a.keypoints_px[:10], c.keypoints_px[:10], equal_nan=True)


def test_params_must_match_camera_count():
    with pytest.raises(ValueError, match="one rate per camera"):
        simulate_capture(_motion(), ring_rig(3), _params(4), np.random.default_rng(0), name="s")


def test_cameras_started_seconds_before_the_capture():
    """Cameras that start at different times.

    start_spread_s: every camera still films the whole window, its frame numbers count from its own start,
    and frame k of camera v lies at offset_v + k / fps_v (drift 0, no jitter).
    """
    fps = (25.0, 30.0, 60.0, 25.0)
    s = _simulate(seed=4, fps_hz=fps, start_spread_s=5.0, image_drop_rate=0.1)
    offsets = np.asarray(s.meta["offsets_s"])
    assert np.all(offsets < 0) and np.all(offsets > -5.0 - 1.0 / 25)
    frame = np.asarray(s.meta["frame_number"])
    for v in range(4):
        sel = s.cam_id == v
        np.testing.assert_allclose(s.timestamp_s[sel], offsets[v] + frame[sel] / fps[v], atol=2e-3)
        first = int(np.ceil(-offsets[v] * fps[v] - 1e-9))
        assert s.stream_index[sel].min() == first  # the video's index runs from the camera's start
        # Dropped frames leave gaps in the camera's own counter, not in the video index.
        assert np.all(np.diff(np.sort(s.stream_index[sel])) == 1)
        assert s.timestamp_s[sel].max() > 2.4 and s.timestamp_s[sel].min() < 0.1
