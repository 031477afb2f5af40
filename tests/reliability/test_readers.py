"""Issue 29, input readers: stray frame files (D11), implausible values (D13), warnings and errors (D16)."""

from __future__ import annotations

import logging
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.calibration import load_calibration
from gttdata.detectors import read_keypoints
from gttdata.errors import CalibrationError, KeypointFormatError, RecipeError
from gttdata.export import export_capture
from gttdata.recipe import load_recipe
from gttdata.recording import Recording, load_project
from gttnet.cli import main as gttnet_main
from tests.fixtures.scenes import make_scene
from tests.reliability.conftest import one_line_error


@pytest.fixture
def sample():
    return make_scene(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=1.0, missing=0.1, seed=3)


def _op(tmp_path, sample):
    return export_capture(sample, tmp_path / "rec", fmt="openpose")


# --- D11: a stray or duplicate OpenPose file is named and skipped, never renumbering the camera ----------


def test_stray_openpose_file_is_named_and_skipped(tmp_path, sample, caplog):
    """A stray del_000001_0.json renumbered every frame of the camera 0..F (frame 5 became 6...)."""
    proj = _op(tmp_path, sample)
    cam = proj.parent / "cam_0"
    before = read_keypoints(cam)
    files = sorted(cam.glob("*.json"))
    shutil.copy(files[1], cam / "del_000001_0.json")
    with caplog.at_level(logging.WARNING):
        after = read_keypoints(cam)
    np.testing.assert_array_equal(after.frame, before.frame)
    np.testing.assert_array_equal(after.xy, before.xy)
    assert "del_000001_0.json" in caplog.text and "skipped" in caplog.text


def test_duplicate_frame_number_is_named_and_skipped(tmp_path, sample, caplog):
    """Two files of frame 1 (cam_0_000000000001_keypoints.json and cam_0_1_keypoints.json) renumbered the camera."""
    proj = _op(tmp_path, sample)
    cam = proj.parent / "cam_0"
    before = read_keypoints(cam)
    shutil.copy(cam / "cam_0_000000000001_keypoints.json", cam / "cam_0_1_keypoints.json")
    with caplog.at_level(logging.WARNING):
        after = read_keypoints(cam)
    keep = before.frame != 1
    np.testing.assert_array_equal(after.frame, before.frame[keep])  # the others keep their numbers
    np.testing.assert_array_equal(after.xy, before.xy[keep])
    assert "cam_0_1_keypoints.json" in caplog.text and "cam_0_000000000001_keypoints.json" in caplog.text


def test_stray_file_warning_on_the_command_line(tmp_path, sample):
    proj = _op(tmp_path, sample)
    cam = proj.parent / "cam_1"
    shutil.copy(sorted(cam.glob("*.json"))[0], cam / "del_000001_0.json")
    res = CliRunner().invoke(gttnet_main, ["reconstruct", str(proj), "--method", "pseudo", "--json"])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "del_000001_0.json" in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "cam_1" in lines[0]


# --- D13: plausibility --------------------------------------------------------------------------------


def _dlc(tmp_path, sample):
    proj = export_capture(sample, tmp_path / "rec", fmt="dlc")
    return proj, proj.parent / "cam_0.csv"


def _set_cell(csv_path, row: int, col: int, value: str) -> None:
    lines = csv_path.read_text().splitlines()
    cells = lines[3 + row].split(",")
    cells[col] = value
    lines[3 + row] = ",".join(cells)
    csv_path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("value", ["inf", "-inf"])
def test_infinite_keypoint_is_refused_naming_file_frame_and_joint(tmp_path, sample, value):
    """An infinite coordinate was read as a missing joint without a word."""
    _, csv_path = _dlc(tmp_path, sample)
    _set_cell(csv_path, 2, 1, value)  # row 2, joint j0's x
    with pytest.raises(KeypointFormatError, match=r"cam_0.csv: frame 2 joint 'j0': expected finite"):
        read_keypoints(csv_path)


def test_keypoints_far_outside_the_image_are_missing_with_a_warning(tmp_path, sample, caplog):
    """-5000 px and 1e300 px were used as detections."""
    proj, csv_path = _dlc(tmp_path, sample)
    _set_cell(csv_path, 1, 1, "-5000")
    _set_cell(csv_path, 3, 5, "1e300")  # row 3, joint j1's y
    _set_cell(csv_path, 3, 6, "1")  # its likelihood
    with caplog.at_level(logging.WARNING):
        rec = Recording.load(load_project(proj))
    kp = rec.keypoints[0]
    assert np.isnan(kp.xy[1, 0]).all() and np.isnan(kp.xy[3, 1]).all()
    assert np.isnan(kp.score[1, 0]) and np.isnan(kp.score[3, 1])
    msgs = [r.getMessage() for r in caplog.records if "outside" in r.getMessage()]
    assert len(msgs) == 1 and "cam_0.csv" in msgs[0] and "'cam_0'" in msgs[0] and "2 keypoint" in msgs[0]
    assert np.isfinite(rec.keypoints[1].xy).any()  # the other cameras are untouched


@pytest.mark.parametrize("k1", ["1e6", "-250.0"])
def test_absurd_distortion_is_refused_naming_file_camera_and_field(tmp_path, sample, k1):
    """k1 = 1e6 was accepted (and undistortion then folded the image onto itself)."""
    proj = _op(tmp_path, sample)
    cal = proj.parent / "calibration.toml"
    text = cal.read_text()
    head, _, tail = text.partition("distortions = [\n    0.0,")
    cal.write_text(f"{head}distortions = [\n    {k1},{tail}")
    with pytest.raises(
        CalibrationError, match=r"calibration.toml: camera 'cam_0': distortion coefficient k1"
    ):
        load_calibration(cal)


def test_plausible_distortion_still_loads(tmp_path, sample):
    proj = _op(tmp_path, sample)
    cal = proj.parent / "calibration.toml"
    cal.write_text(cal.read_text().replace("distortions = [\n    0.0,", "distortions = [\n    -0.35,", 1))
    rig, _ = load_calibration(cal)
    assert rig.cameras[0].dist[0] == -0.35


# --- D16: warnings start with "warning:", errors name their file, duplicate YAML keys, recipe ranges ----


def test_camera_left_out_is_a_warning_line(tmp_path, sample):
    """The warning that a camera without detections is left out printed without its 'warning:' prefix."""
    proj = _op(tmp_path, sample)
    for f in (proj.parent / "cam_2").glob("*.json"):
        f.write_text('{"version": 1.3, "people": []}')
    res = CliRunner().invoke(gttnet_main, ["reconstruct", str(proj), "--method", "pseudo", "--json"])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "left out" in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "cam_2" in lines[0], res.output


def test_python_warnings_are_warning_lines(tmp_path, sample, monkeypatch):
    """A warnings.warn during a command (a solver's RuntimeWarning) printed as 'file.py:123: RuntimeWarning: ...'."""
    import warnings

    import gttnet.methods

    original = gttnet.methods.reconstruct

    def noisy(*a, **k):
        warnings.warn(
            "X-step system not numerically positive definite; using LU", RuntimeWarning, stacklevel=2
        )
        return original(*a, **k)

    monkeypatch.setattr(gttnet.methods, "reconstruct", noisy)
    proj = _op(tmp_path, sample)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        res = CliRunner().invoke(gttnet_main, ["reconstruct", str(proj), "--method", "pseudo", "--json"])
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.output.splitlines() if "positive definite" in ln]
    assert lines == ["warning: X-step system not numerically positive definite; using LU"], res.output


def test_calibration_camera_error_names_the_file(tmp_path, sample):
    """'camera 'cam_0': K must be non-singular' named no file."""
    proj = _op(tmp_path, sample)
    cal = proj.parent / "calibration.toml"
    cal.write_text(cal.read_text().replace("1000.0,", "0.0,", 2))
    with pytest.raises(CalibrationError, match=r"calibration.toml: \[cam_0\] camera 'cam_0': K must be"):
        load_calibration(cal)


def test_duplicate_yaml_key_in_a_recipe_is_refused(tmp_path):
    """PyYAML kept the last of two 'sigma_px' keys without a word."""
    src = (
        "name: dup\nseed: 1\nsplits:\n  - name: train\n    n_samples: 2\n"
        "capture:\n  sigma_px: 1.0\n  fps_hz: 10.0\n  sigma_px: 40.0\n"
    )
    (tmp_path / "r.yaml").write_text(src)
    with pytest.raises(RecipeError) as err:
        load_recipe(tmp_path / "r.yaml")
    msg = str(err.value)
    assert "r.yaml" in msg and "line 9" in msg and "duplicate key 'sigma_px'" in msg and "\n" not in msg


def test_duplicate_yaml_key_in_a_project_file_is_refused(tmp_path, sample):
    proj = _op(tmp_path, sample)
    (proj.parent / "p.yaml").write_text(
        "calibration: calibration.toml\nclock: per-camera\nclock: shared\ncameras:\n"
        + "".join(f"  - {{name: cam_{v}, keypoints: cam_{v}, fps: 30}}\n" for v in range(3))
    )
    with pytest.raises(KeypointFormatError) as err:
        load_project(proj.parent / "p.yaml")
    msg = str(err.value)
    assert "p.yaml" in msg and "line 3" in msg and "duplicate key 'clock'" in msg and "\n" not in msg


@pytest.mark.parametrize(
    "override, key",
    [
        ("train.checkpoint_every=0", "train.checkpoint_every"),
        ("train.log_every=0", "train.log_every"),
        ("train.batch_size=100000", "train.batch_size"),
        ("stages.0.lr=.inf", "stages.0.lr"),
        ("stages.0.lr=-0.1", "stages.0.lr"),
        ("stages.0.plateau_factor=0", "stages.0.plateau_factor"),
        ("seed=-1", "seed"),
        ("data.num_workers=-2", "data.num_workers"),
    ],
)
def test_training_recipe_ranges(override, key):
    """Zero log_every/checkpoint_every stopped training on a ZeroDivisionError, seed=-1 on numpy's check.

    lr = inf or < 0 and batch_size = 100000 were accepted.
    """
    from gttnet.train.recipe import load_train_recipe

    with pytest.raises(RecipeError, match=rf"tiny.yaml: {key}: expected"):
        load_train_recipe("recipes/gttnet/tiny.yaml", [override])


def test_checkpoint_every_zero_on_the_command_line_is_one_line(tmp_path):
    res = CliRunner().invoke(
        gttnet_main,
        ["train", "recipes/gttnet/tiny.yaml", "train.checkpoint_every=0", "--out", str(tmp_path / "run")],
    )
    line = one_line_error(res)
    assert "train.checkpoint_every" in line and ">= 1" in line and not (tmp_path / "run").exists()


@pytest.mark.parametrize("value", [".inf", "-.inf", ".nan"])
def test_non_finite_recipe_numbers_are_refused(value):
    """capture.sigma_px=.inf or .nan was accepted."""
    with pytest.raises(RecipeError, match=r"capture.sigma_px: expected .* \(numbers must be finite\)"):
        load_recipe("recipes/gttdata/tiny.yaml", [f"capture.sigma_px={value}"])


def test_evaluation_recipe_ranges():
    from gttnet.evaluate.recipe import load_eval_recipe

    for override, key in (
        ("workers=0", "workers"),
        ("data.n_sequences=0", "data.n_sequences"),
        ("seed=-3", "seed"),
    ):
        with pytest.raises(RecipeError, match=rf"eval_smoke.yaml: {key}: expected"):
            load_eval_recipe("recipes/gttnet/eval_smoke.yaml", [override])


def test_malformed_opencv_matrix_is_one_line_not_an_abort(tmp_path, sample):
    """An EasyMocap intri.yml whose !!opencv-matrix lacks 'cols' aborted the process inside OpenCV (SIGABRT)."""
    from tests.reliability.conftest import cli
    from tests.reliability.test_reader_fuzz import _easymocap

    proj = export_capture(sample, tmp_path / "op", fmt="openpose")
    _easymocap(tmp_path / "easymocap")
    intri = tmp_path / "easymocap" / "intri.yml"
    text = intri.read_text()
    head, sep, tail = text.partition("K_cam_1: !!opencv-matrix\n")
    intri.write_text(head + sep + tail.replace("   cols: 3\n", "", 1))
    (proj.parent / "project.toml").write_text(
        (proj.parent / "project.toml")
        .read_text()
        .replace('calibration = "calibration.toml"', 'calibration = "../easymocap"')
    )
    res = cli("gttnet", "reconstruct", str(proj), "--method", "pseudo", timeout=300)
    line = one_line_error(res)
    assert "intri.yml" in line and "K_cam_1" in line
