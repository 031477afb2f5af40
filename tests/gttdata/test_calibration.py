"""Calibration files: units stated, given or detected; EasyMocap YAML; distortion; plausibility warnings."""

from __future__ import annotations

import dataclasses
import logging

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gttdata import ring_rig
from gttdata.calibration import (
    check_rig,
    distort_points,
    load_calibration,
    read_easymocap,
    save_calibration,
    undistort_points,
)
from gttdata.cameras import CameraRig
from gttdata.errors import CalibrationError


def _rig(dist=(0.0,) * 5) -> CameraRig:
    rig = ring_rig(3, radius_m=3.0, rng=np.random.default_rng(0), jitter_m=0.1)
    return CameraRig(tuple(dataclasses.replace(c, dist=dist) for c in rig.cameras))


@pytest.mark.parametrize("units", ["m", "cm", "mm"])
def test_toml_units_round_trip(tmp_path, units):
    rig = _rig((-0.3, 0.01, 0.0, 0.0, 0.0))
    save_calibration(rig, tmp_path / "c.toml", units=units)
    back, used = load_calibration(tmp_path / "c.toml")
    assert used == units
    for a, b in zip(rig.cameras, back.cameras, strict=True):
        assert np.abs(a.cam_from_world - b.cam_from_world).max() < 1e-12
        assert a.dist == b.dist and a.name == b.name


def test_unlabelled_mm_file_is_detected_and_logged(tmp_path, caplog):
    rig = _rig()
    save_calibration(rig, tmp_path / "c.toml", units="mm")
    text = (tmp_path / "c.toml").read_text().replace('units = "mm"\n', "")
    (tmp_path / "c.toml").write_text(text)
    with caplog.at_level(logging.WARNING):
        back, used = load_calibration(tmp_path / "c.toml")
    assert used == "mm" and "read as mm" in caplog.text
    assert np.abs(back.cam_from_world - rig.cam_from_world).max() < 1e-12
    # Given explicitly as metres: the implausible rig gets one warning naming the likely mistake.
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        back, used = load_calibration(tmp_path / "c.toml", units="m")
    assert used == "m"
    lines = [r.getMessage() for r in caplog.records]
    assert len(lines) == 1 and "km from the origin" in lines[0] and "--calibration-units mm" in lines[0]


def test_stated_units_conflict_is_an_error(tmp_path):
    save_calibration(_rig(), tmp_path / "c.toml", units="mm")
    with pytest.raises(CalibrationError, match=r"c.toml: field 'metadata.units' says 'mm' but 'm' was given"):
        load_calibration(tmp_path / "c.toml", units="m")


def test_camera_facing_away_is_flagged():
    rig = _rig()
    c = rig.cameras[0]
    T = c.cam_from_world.copy()
    T[:3, :3] = np.diag([-1.0, 1.0, -1.0]) @ T[:3, :3]  # turned around its y axis
    T[:3, 3] = -T[:3, :3] @ c.center
    flipped = CameraRig((dataclasses.replace(c, cam_from_world=T),) + rig.cameras[1:])
    assert check_rig(rig) is None
    assert "cam_0" in check_rig(flipped) and "face away" in check_rig(flipped)


def test_easymocap_yaml(tmp_path):
    rig = _rig((-0.2, 0.0, 0.001, 0.0, 0.0))
    fi = cv2.FileStorage(str(tmp_path / "intri.yml"), cv2.FILE_STORAGE_WRITE)
    fe = cv2.FileStorage(str(tmp_path / "extri.yml"), cv2.FILE_STORAGE_WRITE)
    names = [c.name for c in rig.cameras]
    for fs in (fi, fe):
        fs.startWriteStruct("names", cv2.FileNode_SEQ)
        for n in names:
            fs.write("", n)
        fs.endWriteStruct()
    for c in rig.cameras:
        fi.write(f"K_{c.name}", c.K)
        fi.write(f"dist_{c.name}", np.asarray(c.dist).reshape(1, 5))
        fe.write(f"R_{c.name}", cv2.Rodrigues(c.R)[0])
        fe.write(f"Rot_{c.name}", c.R)
        fe.write(f"T_{c.name}", c.t.reshape(3, 1))
    fi.release()
    fe.release()
    back, units = load_calibration(tmp_path / "intri.yml")
    assert units == "m" and [c.name for c in back.cameras] == names
    for a, b in zip(rig.cameras, back.cameras, strict=True):
        np.testing.assert_allclose(b.cam_from_world, a.cam_from_world, atol=1e-12)
        np.testing.assert_allclose(b.dist, a.dist)
        assert b.image_size == a.image_size  # 2 x principal point
    (tmp_path / "extri.yml").write_text("%YAML:1.0\n---\nnames:\n  - cam_0\n")
    with pytest.raises(CalibrationError, match=r"extri.yml: field 'R_cam_0' is missing"):
        read_easymocap(tmp_path / "intri.yml", tmp_path / "extri.yml")


@settings(max_examples=20, deadline=None)
@given(k1=st.floats(-0.35, 0.2), k2=st.floats(-0.05, 0.05), p=st.floats(-0.002, 0.002))
def test_undistort_inverts_distort(k1, k2, p):
    cam = dataclasses.replace(ring_rig(1)[0], dist=(k1, k2, p, -p, 0.0))
    px = np.random.default_rng(0).uniform(100, 900, (50, 2))
    px[3] = np.nan
    back = undistort_points(distort_points(px, cam), cam)
    np.testing.assert_allclose(back[np.isfinite(back)], px[np.isfinite(px)], atol=1e-6)
    assert np.isnan(back[3]).all()
