"""Tests for Camera and CameraRig: projection/ray properties, two-view triangulation, validation, rig files."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gttdata.cameras import Camera, CameraRig, look_at, ring_rig
from gttdata.errors import RigError

_finite = st.floats(min_value=-1.0, max_value=1.0, allow_nan=False)


def _camera(angle_deg: float, height_m: float = 1.2, f_px: float = 1000.0) -> Camera:
    a = np.deg2rad(angle_deg)
    eye = np.array([3.0 * np.cos(a), 3.0 * np.sin(a), height_m])
    K = np.array([[f_px, 0.0, 500.0], [0.0, f_px * 1.01, 480.0], [0.0, 0.0, 1.0]])
    return Camera(K=K, cam_from_world=look_at(eye, np.array([0.0, 0.0, 0.9])), name=f"c{angle_deg:g}")


def _triangulate_dlt(cams: list[Camera], pixels: list[np.ndarray]) -> np.ndarray:
    """Linear (DLT) triangulation of one point from V views, in homogeneous least squares."""
    rows = []
    for cam, (u, v) in zip(cams, pixels, strict=True):
        P = cam.K @ cam.cam_from_world[:3]
        rows += [u * P[2] - P[0], v * P[2] - P[1]]
    _, _, vt = np.linalg.svd(np.asarray(rows))
    return vt[-1, :3] / vt[-1, 3]


def _triangulate_midpoint(o1, d1, o2, d2) -> np.ndarray:
    """Midpoint of the common perpendicular of two rays ``o + s d``."""
    A = np.array([[d1 @ d1, -d1 @ d2], [d1 @ d2, -d2 @ d2]])
    b = np.array([(o2 - o1) @ d1, (o2 - o1) @ d2])
    s, t = np.linalg.solve(A, b)
    return 0.5 * ((o1 + s * d1) + (o2 + t * d2))


def test_project_smoke_and_shapes():
    cam = _camera(0.0)
    px, depth = cam.project(np.zeros((4, 5, 3)))
    assert px.shape == (4, 5, 2) and depth.shape == (4, 5)
    o, d = cam.pixel_rays(px)
    assert o.shape == d.shape == (4, 5, 3)


def test_look_at_optical_axis_and_centre():
    eye, tgt = np.array([2.0, -1.0, 1.5]), np.array([0.0, 0.5, 1.0])
    cam = Camera(np.diag([800.0, 800, 1]), look_at(eye, tgt))
    np.testing.assert_allclose(cam.center, eye, atol=1e-12)
    px, depth = cam.project(tgt)
    np.testing.assert_allclose(px, [0.0, 0.0], atol=1e-9)
    assert depth == pytest.approx(np.linalg.norm(tgt - eye))
    up_px, _ = cam.project(tgt + np.array([0, 0, 0.1]))
    assert up_px[1] < 0  # world up is image up (-v)


@settings(max_examples=60, deadline=None)
@given(x=_finite, y=_finite, z=_finite, angle=st.floats(0, 360))
def test_project_then_pixel_rays_recovers_point(x, y, z, angle):
    cam = _camera(angle)
    X = np.array([x, y, z + 0.9])
    px, depth = cam.project(X)
    assert depth > 0
    o, d = cam.pixel_rays(px)
    np.testing.assert_allclose(np.linalg.norm(d), 1.0, atol=1e-12)
    # Walk along the ray to the same depth: the optical-axis component of d is depth / distance.
    axis = cam.R[2]
    Xr = o + d * depth / (d @ axis)
    np.testing.assert_allclose(Xr, X, atol=1e-9)
    np.testing.assert_allclose(np.cross(d, X - o), 0.0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(u=st.floats(0, 1000), v=st.floats(0, 960), depth=st.floats(0.1, 50.0), angle=st.floats(0, 360))
def test_pixel_rays_then_project_is_identity(u, v, depth, angle):
    cam = _camera(angle)
    o, d = cam.pixel_rays(np.array([u, v]))
    px, dep = cam.project(o + depth * d)
    np.testing.assert_allclose(px, [u, v], atol=1e-6)
    assert dep > 0


@settings(max_examples=40, deadline=None)
@given(s=st.floats(0.05, 20.0), angle=st.floats(0, 360), u=st.floats(0, 1000), v=st.floats(0, 960))
def test_depth_sign_front_and_behind(s, angle, u, v):
    cam = _camera(angle)
    o, d = cam.pixel_rays(np.array([u, v]))
    _, front = cam.project(o + s * d)
    _, behind = cam.project(o - s * d)
    assert front > 0 > behind
    assert front == pytest.approx(-behind)


@settings(max_examples=50, deadline=None)
@given(
    pts=st.lists(st.tuples(_finite, _finite, _finite), min_size=1, max_size=8),
    a1=st.floats(0, 360),
    gap=st.floats(30, 150),
)
def test_two_view_perfect_calibration_recovers_3d(pts, a1, gap):
    """Project known 3-D points into two calibrated cameras; both triangulators recover them to 1e-9."""
    c1, c2 = _camera(a1, 1.0), _camera(a1 + gap, 1.6)
    X = np.asarray(pts) * 0.8 + np.array([0.0, 0.0, 0.9])
    px1, _ = c1.project(X)
    px2, _ = c2.project(X)
    o1, d1 = c1.pixel_rays(px1)
    o2, d2 = c2.pixel_rays(px2)
    scale = np.linalg.norm(X, axis=-1).max() + 3.0
    for i in range(len(X)):
        mid = _triangulate_midpoint(o1[i], d1[i], o2[i], d2[i])
        dlt = _triangulate_dlt([c1, c2], [px1[i], px2[i]])
        assert np.linalg.norm(mid - X[i]) / scale < 1e-9
        assert np.linalg.norm(dlt - X[i]) / scale < 1e-9


def test_ring_rig_paper_defaults():
    rig = ring_rig()
    assert len(rig) == 4
    assert rig.K.shape == (4, 3, 3) and rig.cam_from_world.shape == (4, 4, 4)
    for cam in rig.cameras:
        horiz = np.linalg.norm(cam.center[:2])
        assert horiz == pytest.approx(3.0)
        px, depth = cam.project(np.array([0.0, 0.0, 0.9]))
        np.testing.assert_allclose(px, [500.0, 500.0], atol=1e-9)
        assert depth > 0


def test_ring_rig_jitter_needs_rng():
    with pytest.raises(ValueError, match="rng"):
        ring_rig(jitter_m=0.1)


def _bad_R() -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.diag([1.0, 1.0, 1.5])
    return T


def _reflection() -> np.ndarray:
    T = np.eye(4)
    T[0, 0] = -1.0
    return T


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"K": np.diag([1000.0, 0.0, 1.0])}, "non-singular"),
        ({"K": np.zeros((3, 3))}, "non-singular"),
        ({"K": np.eye(2)}, r"\(3, 3\)"),
        ({"K": np.diag([np.nan, 1.0, 1.0])}, "finite"),
        ({"cam_from_world": _bad_R()}, "orthonormal"),
        ({"cam_from_world": _reflection()}, "det"),
        ({"cam_from_world": np.eye(3)}, r"\(4, 4\)"),
        ({"image_size": (0, 1000)}, "image_size"),
        ({"image_size": (640, -1)}, "image_size"),
    ],
)
def test_bad_camera_raises_rig_error(kwargs, match):
    args = {"K": np.diag([1000.0, 1000.0, 1.0]), "cam_from_world": np.eye(4), "name": "bad"} | kwargs
    with pytest.raises(RigError, match=match):
        Camera(**args)


def test_empty_rig_raises():
    with pytest.raises(RigError, match="at least one camera"):
        CameraRig(())


def _assert_rigs_equal(a: CameraRig, b: CameraRig) -> None:
    assert len(a) == len(b)
    for ca, cb in zip(a.cameras, b.cameras, strict=True):
        np.testing.assert_allclose(ca.K, cb.K, atol=1e-12)
        np.testing.assert_allclose(ca.cam_from_world, cb.cam_from_world, atol=1e-12)
        assert ca.image_size == cb.image_size
        assert ca.name == cb.name
        np.testing.assert_allclose(ca.dist, cb.dist)


@pytest.mark.parametrize("suffix", [".toml", ".json"])
def test_rig_file_round_trip(tmp_path, suffix):
    rig = ring_rig(5, jitter_m=0.05, jitter_deg=3.0, rng=np.random.default_rng(1), image_size=(1280, 720))
    path = tmp_path / f"rig{suffix}"
    rig.save(path)
    assert not list(tmp_path.glob("*.tmp"))
    _assert_rigs_equal(CameraRig.load(path), rig)


_ANIPOSE_TOML = """\
[cam_0]
name = "A"
size = [ 1920, 1080,]
matrix = [ [ 1400.0, 0.0, 960.0,], [ 0.0, 1400.0, 540.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.1, 0.01, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 0.0, 0.0,]
translation = [ 0.1, -0.2, 3.0,]

[cam_1]
name = "B"
size = [ 1920, 1080,]
matrix = [ [ 1400.0, 0.0, 960.0,], [ 0.0, 1400.0, 540.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.0, 0.0, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 1.5707963267948966, 0.0,]
translation = [ 0.0, 0.0, 2.5,]

[metadata]
adjusted = true
error = 0.42
"""


def test_hand_written_aniposelib_toml(tmp_path):
    path = tmp_path / "calibration.toml"
    path.write_text(_ANIPOSE_TOML)
    rig = CameraRig.load(path)
    assert [c.name for c in rig.cameras] == ["A", "B"]
    a, b = rig.cameras
    assert a.image_size == (1920, 1080)
    np.testing.assert_allclose(a.R, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(a.center, [-0.1, 0.2, -3.0])
    assert a.dist[0] == pytest.approx(-0.1)
    # Rodrigues (0, pi/2, 0) is +90 deg about y: world +x maps to camera -z.
    np.testing.assert_allclose(b.R @ np.array([1.0, 0, 0]), [0, 0, -1], atol=1e-12)
    rig.save(tmp_path / "again.toml")
    _assert_rigs_equal(CameraRig.load(tmp_path / "again.toml"), rig)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("[cam_0]\nname = 'x'\n", "'size' is missing"),
        ("[metadata]\nerror = 0.0\n", "no camera tables"),
        ("[cam_0\n", "cannot parse"),
        (_ANIPOSE_TOML.replace("[ 1400.0, 0.0, 960.0,],", "[ 0.0, 0.0, 0.0,],", 1), "non-singular"),
        (_ANIPOSE_TOML.replace("size = [ 1920, 1080,]", "size = [ 0, 0,]", 1), "image_size"),
    ],
)
def test_bad_rig_file_raises_one_line(tmp_path, text, match):
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(RigError, match=match) as info:
        CameraRig.load(path)
    assert "\n" not in str(info.value)


def test_missing_rig_file(tmp_path):
    with pytest.raises(RigError, match="not found"):
        CameraRig.load(tmp_path / "nope.toml")


def test_rotation_from_vector_matches_opencv():
    # The rig reader's Rodrigues formula in numpy (OpenCV is not loaded to read a calibration).
    import cv2

    from gttdata.cameras import rotation_from_vector

    rng = np.random.default_rng(4)
    for scale in (0.0, 1e-9, 1e-3, 1.0, 3.1):
        r = rng.normal(size=3) * scale
        np.testing.assert_allclose(rotation_from_vector(r), cv2.Rodrigues(r.reshape(3, 1))[0], atol=1e-14)
    with pytest.raises(ValueError, match="finite"):
        rotation_from_vector(np.array([np.nan, 0.0, 0.0]))
