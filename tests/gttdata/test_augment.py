"""Augmentations keep what they must and move what they must.

Augmentations: F^GR keeps the 2-D observations and moves the ground truth by meta['variant_from_orig'];
F^LR re-images the same ground truth consistently; motion edits mirror and scale as documented.
"""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.augment import (
    available_augmentations,
    axis_angle_matrix,
    bone_scale,
    camera_perturbation,
    get_augmentation,
    global_rotation,
    mirror,
    validate_augmentation,
)
from gttdata.cameras import Camera, ring_rig
from gttdata.capture.simulate import CaptureParams, simulate_capture
from gttdata.mocap.motion import Motion
from gttdata.skeleton import cmu31
from tests.fixtures.scenes import body_positions


@pytest.fixture(scope="module")
def sample():
    """4-camera ring 3 m away, 30 Hz each for 1 s, sigma 2 px, 20 % joints dropped."""
    t = np.arange(241) / 120.0
    motion = Motion(body_positions(t, 31, seed=4), 120.0, cmu31(), name="body")
    params = CaptureParams(fps_hz=(30.0,) * 4, duration_s=1.0, sigma_px=2.0, joint_drop_rate=0.2)
    return simulate_capture(motion, ring_rig(4), params, np.random.default_rng(0), name="aug")


def _reprojects(s) -> None:
    for n in range(s.n_images):
        px, _ = Camera(s.K[n], s.cam_from_world[n]).project(s.points3d[n])
        np.testing.assert_allclose(s.keypoints_gt_px[n], px, atol=2e-3)


@pytest.mark.parametrize("axis", ["z", "so3"])
def test_global_rotation_keeps_2d_and_moves_gt(sample, axis: str):
    out = global_rotation(sample, np.random.default_rng(1), axis=axis, max_angle_deg=180.0)
    assert out.variant == "global_rotation" and out.name == sample.name
    assert np.array_equal(out.keypoints_px, sample.keypoints_px, equal_nan=True)
    assert np.array_equal(out.visible, sample.visible)
    assert np.array_equal(out.keypoints_gt_px, sample.keypoints_gt_px, equal_nan=True)
    T = np.asarray(out.meta["variant_from_orig"])
    assert T.shape == (4, 4)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    moved = sample.points3d @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(out.points3d, moved, atol=1e-12)
    assert not np.allclose(out.points3d, sample.points3d)
    _reprojects(out)
    if axis == "z":
        np.testing.assert_allclose(T[2], [0, 0, 1, 0], atol=1e-12)
    assert "variant_from_orig" not in sample.meta  # the original is untouched


def test_camera_perturbation_reimages_consistently(sample):
    out = camera_perturbation(sample, np.random.default_rng(2), rot_deg=2.0, trans_m=0.05)
    assert out.variant == "camera_perturbation"
    np.testing.assert_array_equal(np.asarray(out.meta["variant_from_orig"]), np.eye(4))
    assert np.array_equal(out.points3d, sample.points3d)
    assert not np.allclose(out.cam_from_world, sample.cam_from_world)
    _reprojects(out)
    assert np.all(out.visible <= sample.visible)
    both = out.visible
    err_new = (out.keypoints_px - out.keypoints_gt_px)[both]
    err_old = (sample.keypoints_px - sample.keypoints_gt_px)[both]
    np.testing.assert_allclose(err_new, err_old, atol=1e-3)
    assert np.all(np.isnan(out.keypoints_px[~out.visible]))
    shift = np.linalg.norm(out.keypoints_gt_px - sample.keypoints_gt_px, axis=-1)
    assert 1.0 < np.nanmedian(shift) < 200.0


def test_camera_perturbation_zero_is_identity(sample):
    out = camera_perturbation(sample, np.random.default_rng(3), rot_deg=0.0, trans_m=0.0)
    np.testing.assert_allclose(out.cam_from_world, sample.cam_from_world, atol=1e-12)
    np.testing.assert_allclose(out.keypoints_px, sample.keypoints_px, atol=1e-3)
    assert np.array_equal(out.visible, sample.visible)


def test_registry_lists_and_validates():
    assert set(available_augmentations("capture")) == {"global_rotation", "camera_perturbation"}
    assert set(available_augmentations("motion")) == {
        "mirror",
        "bone_scale",
        "decorrelate",
        "joint_subset",
        "merge_joints",
        "marker_offsets",
    }
    assert get_augmentation("global_rotation").fn is global_rotation
    with pytest.raises(KeyError, match="not registered"):
        get_augmentation("mirror", level="capture")
    assert validate_augmentation("global_rotation", {"axis": "so3"}, level="capture") is None
    assert "params.axis: expected one of 'z', 'so3'" in validate_augmentation(
        "global_rotation", {"axis": "x"}, level="capture"
    )
    assert "params.max_angle_deg: expected a number in [0, 180]" in validate_augmentation(
        "global_rotation", {"max_angle_deg": 400}, level="capture"
    )


def test_axis_angle_matrix_matches_closed_form():
    R = axis_angle_matrix(np.array([0.0, 0.0, np.pi / 2]))
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(axis_angle_matrix(np.zeros((2, 3))), np.stack([np.eye(3)] * 2))


def _motion() -> Motion:
    t = np.arange(121) / 120.0
    return Motion(body_positions(t, 31, seed=2), 120.0, cmu31(), name="m")


def test_mirror_motion():
    m = _motion()
    assert mirror(m, np.random.default_rng(0), prob=0.0) is m
    out = mirror(m, np.random.default_rng(0), prob=1.0)
    flip = m.skeleton.flip_index()
    np.testing.assert_allclose(out.positions[:, :, 1], -m.positions[:, flip, 1])
    np.testing.assert_allclose(out.positions[:, :, [0, 2]], m.positions[:, flip][:, :, [0, 2]])


def test_bone_scale_motion():
    m = _motion()
    out = bone_scale(m, np.random.default_rng(0), factor=1.1)
    np.testing.assert_allclose(out.bone_lengths(), 1.1 * m.bone_lengths(), rtol=1e-10)
    assert out.positions[..., 2].min() == pytest.approx(m.positions[..., 2].min())
    assert bone_scale(m, np.random.default_rng(0), factor=1.0) is m
    jit = bone_scale(m, np.random.default_rng(0), factor=1.0, per_bone_std=0.05)
    ratio = jit.bone_lengths()[0] / m.bone_lengths()[0]
    assert not np.allclose(ratio, 1.0)
