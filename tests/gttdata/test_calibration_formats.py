"""Qualisys, Vicon, Caliscope and FreeMoCap calibrations: round trips, known values, units from the file."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

from gttdata import ring_rig
from gttdata.calibration import load_calibration, save_calibration
from gttdata.calibration_formats import write_qca, write_xcp
from gttdata.cameras import CameraRig
from gttdata.errors import CalibrationError


def _rig(dist=(-0.2, 0.03, 0.001, -0.002)) -> CameraRig:
    rig = ring_rig(4, radius_m=3.0, rng=np.random.default_rng(1), jitter_m=0.1)
    return CameraRig(
        tuple(dataclasses.replace(c, dist=dist, name=f"{1000 + 7 * i}") for i, c in enumerate(rig.cameras))
    )


@pytest.mark.parametrize("writer, suffix", [(write_qca, ".qca.txt"), (write_xcp, ".xcp")])
def test_round_trip(tmp_path, writer, suffix):
    rig = _rig((-0.2, 0.03, 0.0, 0.0) if suffix == ".xcp" else (-0.2, 0.03, 0.001, -0.002))
    path = writer(rig, tmp_path / f"calib{suffix}")
    back, units = load_calibration(path)
    assert units == "mm"
    assert [c.name for c in back.cameras] == [c.name for c in rig.cameras]
    for a, b in zip(rig.cameras, back.cameras, strict=True):
        np.testing.assert_allclose(b.cam_from_world, a.cam_from_world, atol=1e-9)
        np.testing.assert_allclose(b.K, a.K, atol=1e-9)
        np.testing.assert_allclose(b.dist[:2], a.dist[:2], atol=1e-12)
        assert b.image_size == a.image_size


QCA = """<?xml version="1.0"?>
<calibration>
 <cameras>
  <camera active="1" avg-residual="0.2" serial="22222" model="Miqus Video">
   <fov_video left="10" top="20" right="1929" bottom="1099"/>
   <transform x="0" y="0" z="3000" r11="1" r12="0" r13="0" r21="0" r22="1" r23="0" r31="0" r32="0" r33="1"/>
   <intrinsic focalLengthU="64000" focalLengthV="64000" centerPointU="62080" centerPointV="35840"
     radialDistortion1="0" radialDistortion2="0" tangentalDistortion1="0" tangentalDistortion2="0"/>
  </camera>
  <camera active="1" avg-residual="0.3" serial="11111" model="Miqus M3">
   <fov_video left="0" top="0" right="1000" bottom="1000"/>
   <transform x="0" y="0" z="0" r11="1" r12="0" r13="0" r21="0" r22="1" r23="0" r31="0" r32="0" r33="1"/>
   <intrinsic focalLengthU="64" focalLengthV="64" centerPointU="0" centerPointV="0"
     radialDistortion1="0" radialDistortion2="0" tangentalDistortion1="0" tangentalDistortion2="0"/>
  </camera>
 </cameras>
</calibration>
"""


def test_qca_known_values(tmp_path):
    """A video camera 3 m above the origin looking down; the marker camera is left out."""
    (tmp_path / "c.qca.txt").write_text(QCA)
    rig, units = load_calibration(tmp_path / "c.qca.txt")
    assert units == "mm" and [c.name for c in rig.cameras] == ["22222"]
    cam = rig.cameras[0]
    np.testing.assert_allclose(cam.center, [0, 0, 3.0], atol=1e-12)
    np.testing.assert_allclose(cam.K, [[1000, 0, 960], [0, 1000, 540], [0, 0, 1]])  # 62080/64 - 10
    assert cam.image_size == (1920, 1080)
    np.testing.assert_allclose(cam.R[2], [0, 0, -1], atol=1e-12)  # optical axis points down
    uv, depth = cam.project(np.array([[0.3, 0.0, 0.0]]))
    np.testing.assert_allclose(uv, [[960 + 1000 * 0.3 / 3.0, 540]], atol=1e-9)
    np.testing.assert_allclose(depth, [3.0])


XCP = """<?xml version="1.0"?>
<Cameras VERSION="1.0">
 <Camera DEVICEID="2" TYPE="VIDEO" SENSOR_SIZE="1920 1080" PIXEL_ASPECT_RATIO="1">
  <KeyFrames><KeyFrame FOCAL_LENGTH="1200" PRINCIPAL_POINT="950 530" VICON_RADIAL2="0 0 0 -0.1 0.02"
     ORIENTATION="1 0 0 0" POSITION="0 0 2500" WORLD_ERROR="0.1"/></KeyFrames>
 </Camera>
 <Camera DEVICEID="1" TYPE="T160" SENSOR_SIZE="4704 3456" PIXEL_ASPECT_RATIO="1">
  <KeyFrames><KeyFrame FOCAL_LENGTH="1" PRINCIPAL_POINT="0 0" VICON_RADIAL="0 0"
     ORIENTATION="0 0 0 1" POSITION="0 0 0" WORLD_ERROR="0.1"/></KeyFrames>
 </Camera>
</Cameras>
"""


def test_xcp_known_values(tmp_path):
    """Quaternion (1, 0, 0, 0) is a half turn about x: the camera 2.5 m up looks down; markers left out."""
    (tmp_path / "c.xcp").write_text(XCP)
    rig, units = load_calibration(tmp_path / "c.xcp")
    assert units == "mm" and [c.name for c in rig.cameras] == ["2"]
    cam = rig.cameras[0]
    np.testing.assert_allclose(cam.center, [0, 0, 2.5], atol=1e-12)
    np.testing.assert_allclose(cam.R, np.diag([1.0, -1.0, -1.0]), atol=1e-12)
    assert cam.dist[:2] == (-0.1, 0.02) and cam.K[0, 2] == 950


CALISCOPE = """
[cameras.0]
cam_id = 0
size = [1280, 720]
matrix = [[900.0, 0.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]]
distortions = [-0.1, 0.01, 0.0, 0.0, 0.0]
rotation = [3.141592653589793, 0.0, 0.0]
translation = [0.0, 0.0, 2.0]
error = 0.4
grid_count = 12

[cameras.1]
cam_id = 1
size = [1280, 720]
matrix = [[900.0, 0.0, 640.0], [0.0, 900.0, 360.0], [0.0, 0.0, 1.0]]
distortions = [0.0, 0.0, 0.0, 0.0, 0.0]
"""


def test_caliscope_known_values(tmp_path):
    """Rodrigues (pi, 0, 0) with translation (0, 0, 2) m: centre 2 m above the origin; unposed camera left out."""
    (tmp_path / "camera_array.toml").write_text(CALISCOPE)
    rig, units = load_calibration(tmp_path / "camera_array.toml")
    assert units == "m" and [c.name for c in rig.cameras] == ["cam_0"]
    np.testing.assert_allclose(rig.cameras[0].center, [0, 0, 2.0], atol=1e-9)
    with pytest.raises(CalibrationError, match="unit, 'm'"):
        load_calibration(tmp_path / "camera_array.toml", units="mm")


def test_freemocap_toml_is_millimetres(tmp_path):
    """FreeMoCap's aniposelib TOML (ChArUco square in mm) is read in mm even for a small rig."""
    import tomllib

    import tomli_w

    rig = ring_rig(3, radius_m=0.03, rng=np.random.default_rng(0))  # 30 "units": spread below the mm guess
    path = save_calibration(rig, tmp_path / "c.toml", units="m")
    d = tomllib.loads(path.read_text())
    d["metadata"] = {"adjusted": False, "error": 0.5, "charuco_square_size": 39.0}
    (tmp_path / "rec_camera_calibration.toml").write_text(tomli_w.dumps(d))
    back, units = load_calibration(tmp_path / "rec_camera_calibration.toml", warn=False)
    assert units == "mm"
    np.testing.assert_allclose(back.cameras[0].center, rig.cameras[0].center * 1e-3, atol=1e-12)


class _Bomb:
    def __reduce__(self):
        return (open, ("/tmp/gtt_opencap_pickle_ran", "w"))


def test_opencap_pickle_that_calls_anything_runs_nothing(tmp_path):
    import os

    marker = "/tmp/gtt_opencap_pickle_ran"
    if os.path.exists(marker):
        os.remove(marker)
    (tmp_path / "cam0.pickle").write_bytes(pickle.dumps(_Bomb()))
    with pytest.raises(CalibrationError, match="nothing in it was run") as exc:
        load_calibration(tmp_path / "cam0.pickle")
    assert not os.path.exists(marker) and "\n" not in str(exc.value)
    # A global that is not one of numpy's array constructors is refused too (here a harmless one).
    import collections

    (tmp_path / "cam0.pickle").write_bytes(pickle.dumps(collections.OrderedDict(a=1)))
    with pytest.raises(CalibrationError, match="global collections.OrderedDict"):
        load_calibration(tmp_path / "cam0.pickle")


def _opencap(folder, name, *, centre_board, protocol=pickle.DEFAULT_PROTOCOL):
    """An OpenCap pickle of a camera at ``centre_board`` (board frame, metres) looking at the board origin."""
    c = np.asarray(centre_board, dtype=np.float64)
    z = -c / np.linalg.norm(c)
    x = np.cross(np.array([0.0, -1.0, 0.0]), z)  # board frame: y points down the board
    x /= np.linalg.norm(x)
    R = np.stack([x, np.cross(z, x), z])
    d = {
        "intrinsicMat": np.array([[1400.0, 0, 960], [0, 1400.0, 540], [0, 0, 1]]),
        "distortion": np.array([[0.01, -0.02, 0.001, 0.002, 0.0]]),
        "imageSize": np.array([[1080], [1920]]),
        "rotation": R,
        "translation": (-R @ c * 1000.0).reshape(3, 1),
    }
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).write_bytes(pickle.dumps(d, protocol=protocol))


@pytest.mark.parametrize("protocol", [2, 4, 5])
def test_opencap_session_reads_as_one_rig_in_our_world(tmp_path, protocol):
    """OpenCap's layout (Videos/CamN/cameraIntrinsicsExtrinsics.pickle), board frame turned to z up."""
    name = "cameraIntrinsicsExtrinsics.pickle"
    _opencap(tmp_path / "Cam0", name, centre_board=[0.0, -1.5, 3.0], protocol=protocol)  # 1.5 m up, 3 m out
    _opencap(tmp_path / "Cam1", name, centre_board=[2.0, -1.0, 2.0], protocol=protocol)
    rig, units = load_calibration(tmp_path / "Cam0" / name, warn=False)
    assert units == "mm" and [c.name for c in rig.cameras] == ["Cam0", "Cam1"]
    cam = rig.cameras[0]
    np.testing.assert_allclose(cam.center, [0.0, -3.0, 1.5], atol=1e-9)  # height is +z in our world
    np.testing.assert_allclose(rig.cameras[1].center, [-2.0, -2.0, 1.0], atol=1e-9)
    assert cam.image_size == (1920, 1080) and cam.K[0, 0] == 1400.0
    np.testing.assert_allclose(cam.dist[:4], [0.01, -0.02, 0.001, 0.002])
    px, depth = cam.project(np.zeros((1, 3)))  # the board origin is where it looked
    np.testing.assert_allclose(px[0], [960.0, 540.0], atol=1e-6)
    assert depth[0] > 0


def test_opencap_missing_field_names_it(tmp_path):
    import pickle as pk

    (tmp_path / "c.pickle").write_bytes(pk.dumps({"intrinsicMat": np.eye(3)}))
    with pytest.raises(CalibrationError, match=r"c\.pickle: field 'distortion'"):
        load_calibration(tmp_path / "c.pickle")


def test_qca_errors_name_file_and_field(tmp_path):
    (tmp_path / "c.qca.txt").write_text(QCA.replace('focalLengthU="64000"', 'focalLengthU="abc"'))
    with pytest.raises(CalibrationError, match=r"c\.qca\.txt: camera '22222' field 'focalLengthU'"):
        load_calibration(tmp_path / "c.qca.txt")
    (tmp_path / "bad.qca.txt").write_text("<calibration><cameras>")
    with pytest.raises(CalibrationError, match="not a readable XML"):
        load_calibration(tmp_path / "bad.qca.txt")


def test_optitrack_calibration_is_refused_by_name(tmp_path):
    (tmp_path / "cal.mcal").write_text("<calibration/>")
    with pytest.raises(CalibrationError, match="OptiTrack calibrations are not read"):
        load_calibration(tmp_path / "cal.mcal")
