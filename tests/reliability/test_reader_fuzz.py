"""Property tests of every input reader: a mutated valid file gives a result or ONE project error line.

Each reader gets valid files (an exported recording, a calibration, recipes, GTT-Net JSON, a DLOE .mat)
mutated at one place: a value of the wrong type, NaN or inf, an absurd or negative number, a missing
key, an empty or nested list, a cut or garbage line. The property: the reader returns, or raises a
:class:`~gttdata.errors.GttDataError` (or an ``OSError`` naming a file) whose message is one line;
never another exception (a traceback on the command line). The default run tries a few examples per
reader; ``-m slow`` runs many more.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import tomli_w
import yaml
from hypothesis import HealthCheck, assume, given, settings

from gttdata.errors import GttDataError
from tests.reliability import _mutate

REPO = Path(__file__).resolve().parents[2]
FAST = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture], database=None
)
MANY = settings(
    max_examples=400,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture],
    database=None,
)


def project_error_or_result(fn) -> None:
    """Run ``fn``: it returns, or raises a one-line project error (or an OSError naming its file)."""
    try:
        fn()
    except GttDataError as exc:
        msg = str(exc)
        assert msg.strip() and "\n" not in msg.strip(), f"not one line: {msg!r}"
    except OSError as exc:
        assert exc.filename, f"an OSError without a file name: {exc!r}"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    """An exported recording (OpenPose and DeepLabCut) of a small synthetic capture, plus COCO/MMPose files."""
    from gttdata.detectors import read_keypoints, write_keypoints
    from gttdata.export import export_capture
    from tests.fixtures.scenes import make_scene

    root = tmp_path_factory.mktemp("fuzz")
    sample = make_scene(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=1.0, missing=0.2, seed=3)
    export_capture(sample, root / "op", fmt="openpose")
    export_capture(sample, root / "dlc", fmt="dlc")
    kp = read_keypoints(root / "op" / "cam_0")
    write_keypoints(kp, root / "coco.json", "coco")
    mmpose = {
        "meta_info": {"keypoint_id2name": {str(j): n for j, n in enumerate(kp.joint_names)}},
        "instance_info": [
            {
                "frame_id": int(f),
                "instances": [
                    {
                        "keypoints": np.nan_to_num(xy).tolist(),
                        "keypoint_scores": np.nan_to_num(sc).tolist(),
                    }
                ],
            }
            for f, xy, sc in zip(kp.frame, kp.xy, kp.score, strict=True)
        ],
    }
    (root / "mmpose.json").write_text(json.dumps(mmpose))
    return root


def _work(tmp_path: Path, src: Path) -> Path:
    dst = tmp_path / "w"
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(src, dst)
    return dst


# --- detector files ---------------------------------------------------------------------------------


def _openpose_case(recording, tmp_path, path, op):
    from gttdata.detectors.openpose import read_openpose

    w = _work(tmp_path, recording / "op" / "cam_0")
    first = sorted(w.glob("*.json"))[0]
    doc = json.loads(first.read_text())
    first.write_text(json.dumps(_mutate.apply(doc, path, op)))
    project_error_or_result(lambda: read_openpose(w))


def _coco_case(recording, tmp_path, name, path, op):
    from gttdata.detectors.coco import read_coco

    doc = json.loads((recording / name).read_text())
    f = tmp_path / name
    f.write_text(json.dumps(_mutate.apply(doc, path, op)))
    project_error_or_result(lambda: read_coco(f))


def _dlc_case(tmp_path, text):
    from gttdata.detectors.dlc import read_dlc

    f = tmp_path / "cam.csv"
    f.write_text(text)
    project_error_or_result(lambda: read_dlc(f))


def _op_doc(recording):
    return json.loads(sorted((recording / "op" / "cam_0").glob("*.json"))[0].read_text())


def test_openpose_frame_file_mutations(recording, tmp_path):
    @FAST
    @given(m=_mutate.doc_mutations(_op_doc(recording)))
    def run(m):
        _openpose_case(recording, tmp_path, *m)

    run()


def _coco_runner(recording, tmp_path, name, cfg):
    @cfg
    @given(m=_mutate.doc_mutations(json.loads((recording / name).read_text())))
    def run(m):
        _coco_case(recording, tmp_path, name, *m)

    return run


@pytest.mark.parametrize("name", ["coco.json", "mmpose.json"])
def test_coco_and_mmpose_mutations(recording, tmp_path, name):
    _coco_runner(recording, tmp_path, name, FAST)()


def test_dlc_csv_mutations(recording, tmp_path):
    text = (recording / "dlc" / "cam_0.csv").read_text()

    @FAST
    @given(t=_mutate.text_mutations(text))
    def run(t):
        _dlc_case(tmp_path, t)

    run()


# --- calibrations, timestamps and project files -----------------------------------------------------


def _toml_text(doc) -> str:
    try:
        return tomli_w.dumps(doc)
    except (TypeError, ValueError):  # None or a non-table root: TOML cannot hold it
        assume(False)
        raise


def _calibration_case(recording, tmp_path, path, op):
    from gttdata.calibration import load_calibration

    doc = yaml.safe_load(json.dumps(_toml_doc(recording / "op" / "calibration.toml")))
    mutated = _mutate.apply(doc, path, op)
    assume(isinstance(mutated, dict))
    f = tmp_path / "c.toml"
    f.write_text(_toml_text(mutated))
    project_error_or_result(lambda: load_calibration(f))


def _toml_doc(path: Path) -> dict:
    import tomllib

    return tomllib.loads(path.read_text())


def test_calibration_toml_mutations(recording, tmp_path):
    @FAST
    @given(m=_mutate.doc_mutations(_toml_doc(recording / "op" / "calibration.toml")))
    def run(m):
        _calibration_case(recording, tmp_path, *m)

    run()


def _easymocap(folder: Path) -> None:
    import cv2

    from gttdata.calibration import load_calibration

    rig, _ = load_calibration(folder.parent / "op" / "calibration.toml", warn=False)
    folder.mkdir(exist_ok=True)
    fi = cv2.FileStorage(str(folder / "intri.yml"), cv2.FILE_STORAGE_WRITE)
    fe = cv2.FileStorage(str(folder / "extri.yml"), cv2.FILE_STORAGE_WRITE)
    for fs in (fi, fe):
        fs.startWriteStruct("names", cv2.FileNode_SEQ)
        for c in rig.cameras:
            fs.write("", c.name)
        fs.endWriteStruct()
    for c in rig.cameras:
        fi.write(f"K_{c.name}", c.K)
        fi.write(f"dist_{c.name}", np.asarray(c.dist).reshape(1, 5))
        fe.write(f"R_{c.name}", cv2.Rodrigues(c.R)[0])
        fe.write(f"T_{c.name}", c.t.reshape(3, 1))
    fi.release()
    fe.release()


def test_easymocap_mutations(recording, tmp_path):
    from gttdata.calibration import load_calibration

    _easymocap(recording / "easymocap")
    for name in ("intri.yml", "extri.yml"):
        text = (recording / "easymocap" / name).read_text()

        @FAST
        @given(t=_mutate.text_mutations(text))
        def run(t):
            w = _work(tmp_path, recording / "easymocap")
            (w / name).write_text(t)  # noqa: B023 - run() is called inside this iteration
            project_error_or_result(lambda: load_calibration(w))

        run()


def test_timestamp_csv_mutations(recording, tmp_path):
    from gttdata.recording import read_timestamps_csv

    text = (recording / "op" / "cam_0_timestamps.csv").read_text()

    @FAST
    @given(t=_mutate.text_mutations(text))
    def run(t):
        f = tmp_path / "ts.csv"
        f.write_text(t)
        project_error_or_result(lambda: read_timestamps_csv(f))

    run()


def _project_case(recording, tmp_path, path, op, suffix):
    from gttdata.recording import Recording, load_project

    w = _work(tmp_path, recording / "op")
    doc = _toml_doc(w / "project.toml")
    mutated = _mutate.apply(doc, path, op)
    f = w / f"p{suffix}"
    if suffix == ".toml":
        assume(isinstance(mutated, dict))
        f.write_text(_toml_text(mutated))
    else:
        f.write_text(yaml.safe_dump(mutated))

    def load():
        view = Recording.load(load_project(f)).view()
        assert view.observations.n_images > 0

    project_error_or_result(load)


@pytest.mark.parametrize("suffix", [".toml", ".yaml"])
def test_project_file_mutations(recording, tmp_path, suffix):
    @FAST
    @given(m=_mutate.doc_mutations(_toml_doc(recording / "op" / "project.toml")))
    def run(m):
        _project_case(recording, tmp_path, *m, suffix)

    run()


# --- gttnet inputs ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def gttnet_json(tmp_path_factory) -> Path:
    from gttnet.io.gttnet_json import write_gttnet_json
    from tests.fixtures.scenes import make_scene

    path = tmp_path_factory.mktemp("gj") / "cap.json"
    write_gttnet_json(make_scene(n_cameras=3, n_joints=4, frames_per_camera=5, seed=1), path)
    return path


def test_gttnet_json_mutations(gttnet_json, tmp_path):
    from gttnet.io import load_input

    doc = json.loads(gttnet_json.read_text())
    doc.pop("X_init")
    doc.pop("rayDInd")

    @FAST
    @given(m=_mutate.doc_mutations(doc))
    def run(m):
        f = tmp_path / "g.json"
        f.write_text(json.dumps(_mutate.apply(doc, *m)))
        project_error_or_result(lambda: load_input(f, sequencing="none"))

    run()


def test_dloe_mat_mutations(tmp_path):
    import scipy.io

    from gttnet.io import load_input
    from tests.fixtures.scenes import make_scene
    from tests.gttnet.test_importers import dloe_mat_dict

    d = dloe_mat_dict(make_scene(n_cameras=3, n_joints=4, frames_per_camera=5, seed=1))
    keys = [("X_GT",)] + [("caminput", k) for k in d["caminput"]]
    values = [None, "abc", np.nan, np.inf, -1.0, 0.0, 1e300, np.zeros((0,)), np.ones((2, 2)), "delete"]
    from hypothesis import strategies as st

    @FAST
    @given(key=st.sampled_from(keys), value=st.sampled_from(values), cell=st.booleans())
    def run(key, value, cell):
        mat = {"caminput": dict(d["caminput"]), "X_GT": d["X_GT"]}
        node = mat if len(key) == 1 else mat["caminput"]
        if value is None or (isinstance(value, str) and value == "delete"):
            node.pop(key[-1])
        elif cell and isinstance(node[key[-1]], np.ndarray) and node[key[-1]].dtype == object:
            arr = node[key[-1]].copy()
            arr[0, 0] = value
            node[key[-1]] = arr
        else:
            node[key[-1]] = value
        f = tmp_path / "d.mat"
        scipy.io.savemat(str(f), mat)
        project_error_or_result(lambda: load_input(f, sequencing="none"))

    run()


# --- recipes ------------------------------------------------------------------------------------------


def _recipe_doc(name: str) -> dict:
    return yaml.safe_load((REPO / "recipes" / name).read_text())


RECIPE_VALUES = (*_mutate.BAD_VALUES, 0, -1, math.inf, 1e12)


def _recipe_parse(kind: str):
    if kind == "gttdata/tiny.yaml":
        from gttdata.recipe import parse_recipe

        return lambda d: parse_recipe(d, source="tiny.yaml")
    if kind == "gttnet/tiny.yaml":
        from gttnet.train.recipe import parse_train_recipe

        return lambda d: parse_train_recipe(d, source="tiny.yaml")
    from gttnet.evaluate.recipe import parse_eval_recipe

    return lambda d: parse_eval_recipe(d, source="eval_smoke.yaml")


def _recipe_runner(kind, cfg):
    doc, parse = _recipe_doc(kind), _recipe_parse(kind)

    @cfg
    @given(m=_mutate.doc_mutations(doc, RECIPE_VALUES))
    def run(m):
        mutated = _mutate.apply(doc, *m)
        assume(isinstance(mutated, dict))
        project_error_or_result(lambda: parse(mutated))

    return run


@pytest.mark.parametrize("kind", ["gttdata/tiny.yaml", "gttnet/tiny.yaml", "gttnet/eval_smoke.yaml"])
def test_recipe_mutations(kind):
    _recipe_runner(kind, FAST)()


# --- many more examples (slow) ------------------------------------------------------------------------


@pytest.mark.slow
def test_many_mutations_of_every_reader(recording, gttnet_json, tmp_path):
    """The same properties with hundreds of examples each."""
    from gttnet.io import load_input

    @MANY
    @given(m=_mutate.doc_mutations(_op_doc(recording)))
    def op(m):
        _openpose_case(recording, tmp_path, *m)

    @MANY
    @given(m=_mutate.doc_mutations(_toml_doc(recording / "op" / "calibration.toml")))
    def cal(m):
        _calibration_case(recording, tmp_path, *m)

    @MANY
    @given(m=_mutate.doc_mutations(_toml_doc(recording / "op" / "project.toml")))
    def proj(m):
        _project_case(recording, tmp_path, *m, ".toml")

    @MANY
    @given(t=_mutate.text_mutations((recording / "dlc" / "cam_0.csv").read_text()))
    def dlc(t):
        _dlc_case(tmp_path, t)

    doc = json.loads(gttnet_json.read_text())

    @MANY
    @given(m=_mutate.doc_mutations(doc))
    def gj(m):
        f = tmp_path / "g.json"
        f.write_text(json.dumps(_mutate.apply(doc, *m)))
        project_error_or_result(lambda: load_input(f, sequencing="none"))

    for name in ("coco.json", "mmpose.json"):
        _coco_runner(recording, tmp_path, name, MANY)()
    for run in (op, cal, proj, dlc, gj):
        run()
    for kind in ("gttdata/tiny.yaml", "gttnet/tiny.yaml", "gttnet/eval_smoke.yaml"):
        _recipe_runner(kind, MANY)()


# --- SLEAP (sleap-io faked: the optional package is not installed here) -------------------------------


class _FakeInstance:
    def __init__(self, points, scored):
        self.points, self.scored = points, scored
        if scored:
            self.score = 1.0

    def numpy(self, scores=False):
        return self.points


class _FakeFrame:
    def __init__(self, video, frame_idx, instances):
        self.video, self.frame_idx, self.instances = video, frame_idx, instances


class _FakeLabels:
    def __init__(self, names, frames, video):
        self.skeletons = [type("S", (), {"node_names": names})()]
        self.videos = [video]
        self.labeled_frames = frames


def test_sleap_reader_with_odd_contents(tmp_path, monkeypatch):
    """Odd point arrays, frame indices and skeletons from sleap-io give a result or one line."""
    import sys
    import types

    from hypothesis import strategies as st

    from gttdata.detectors.sleap import read_sleap

    path = tmp_path / "cam.slp"
    path.write_bytes(b"")
    points = st.sampled_from(
        [np.ones((3, 3)), np.ones((3, 2)), np.ones((4, 3)), np.full((3, 3), np.inf), np.full((3, 3), np.nan),
         np.ones((3,)), np.ones((0, 3)), np.array([["a", "b", "c"]] * 3)]
    )  # fmt: skip
    frame_idx = st.sampled_from([0, 1, -1, 2**70, 1.5, "x", None])

    @FAST
    @given(pts=st.lists(st.tuples(points, frame_idx, st.booleans()), max_size=4))
    def run(pts):
        video = types.SimpleNamespace(filename="cam.mp4")
        frames = [_FakeFrame(video, f, [_FakeInstance(p, s)]) for p, f, s in pts]
        fake = types.SimpleNamespace(load_slp=lambda _: _FakeLabels(("a", "b", "c"), frames, video))
        monkeypatch.setitem(sys.modules, "sleap_io", fake)
        project_error_or_result(lambda: read_sleap(path))

    run()
