"""Audit replay: malformed inputs through the command lines, counting tracebacks, crashes and one-line errors.

A few valid fixtures (an exported OpenPose and DeepLabCut recording, a GTT-Net JSON file, the tiny recipes
and dataset) are mutated one place at a time: a calibration or project field given a wrong type, NaN,
inf or an absurd number, or deleted; an OpenPose frame file, DeepLabCut CSV or timestamp file damaged;
a recipe override out of range; a shard or manifest damaged. Each case runs one command
(``gttnet reconstruct``, ``gttnet sync``, ``gttdata generate``, ``gttdata verify``, ``gttnet train``,
``gttnet evaluate``) and is classified:

* ``ok``: exit 0 (the mutation was harmless or repaired, e.g. a stray field);
* ``one-line``: non-zero exit with exactly one ``Error:`` line and no traceback;
* ``multi-line``: non-zero exit with another shape of message;
* ``traceback``: a Python traceback or an exception other than the project's (in-process: click's
  runner caught a non-``SystemExit`` exception);
* ``segfault``: killed by a signal (``--subprocess`` only; in process a crash takes the runner down).

Run ``python -m tests.reliability.audit_replay`` (in process, about a minute) or add ``--subprocess`` (each
case a real ``python -m gttnet``/``gttdata`` process; several minutes). It prints one table row per
command. ``tests/reliability/test_audit_replay.py`` runs a fast subset by default and every case under
``-m slow``, and asserts no traceback, no crash and one line for every failure.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import tomli_w

REPO = Path(__file__).resolve().parents[2]
OUTCOMES = ("ok", "one-line", "multi-line", "traceback", "segfault")

#: Replacement values of the document mutations ("<delete>" removes the key).
VALUES: tuple[object, ...] = ("abc", math.nan, math.inf, -1, 0, 1e6, -5000.0, [], {}, "<delete>")


@dataclass(frozen=True)
class Case:
    """One replayed command.

    Args:
        name: What was damaged, for the report.
        program: ``gttnet`` or ``gttdata``.
        prepare: ``prepare(workdir) -> argv`` copies and damages the fixture files in ``workdir`` (empty,
            one per case) and returns the command's arguments.
    """

    name: str
    program: str
    prepare: Callable[[Path], list[str]]

    @property
    def command(self) -> str:
        """``gttnet reconstruct`` etc., the table's row."""
        return f"{self.program} {self.name.split(':')[0]}"


@dataclass(frozen=True)
class Result:
    """The outcome of one case (one of :data:`OUTCOMES`) and the command's output."""

    case: Case
    outcome: str
    output: str
    seconds: float


# --- fixtures -------------------------------------------------------------------------------------------


def build_fixtures(root: Path) -> Path:
    """Write the valid fixtures under ``root`` (recordings, a GTT-Net JSON file, recipes, a tiny dataset)."""
    from click.testing import CliRunner

    from gttdata.cli import main as gttdata_main
    from gttdata.export import export_capture
    from gttnet.io.gttnet_json import write_gttnet_json
    from tests.fixtures.scenes import make_scene

    sample = make_scene(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=1.0, missing=0.1, seed=3)
    export_capture(sample, root / "op", fmt="openpose")
    export_capture(sample, root / "dlc", fmt="dlc")
    write_gttnet_json(make_scene(n_cameras=3, n_joints=4, frames_per_camera=5, seed=1), root / "cap.json")
    res = CliRunner().invoke(
        gttdata_main,
        ["generate", str(REPO / "recipes/gttdata/tiny.yaml"), "--out", str(root / "tiny"), "--no-progress"],
    )
    if res.exit_code != 0:
        raise RuntimeError(f"the tiny dataset did not generate: {res.output}")
    return root


def _copy(src: Path, dst: Path) -> Path:
    if src.is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copy(src, dst)
    return dst


def _set(doc: object, path: tuple, value: object) -> object:
    node = doc
    for k in path[:-1]:
        node = node[k]  # type: ignore[index]
    if value == "<delete>":
        if isinstance(node, dict):
            node.pop(path[-1], None)
        else:
            del node[path[-1]]  # type: ignore[union-attr]
    else:
        node[path[-1]] = value  # type: ignore[index]
    return doc


def _toml_case(fx: Path, rec: str, file: str, path: tuple, value: object, argv: Callable[[Path], list[str]]):
    def prepare(work: Path) -> list[str]:
        d = _copy(fx / rec, work / rec)
        doc = _set(tomllib.loads((d / file).read_text()), path, value)
        try:
            (d / file).write_text(tomli_w.dumps(doc))
        except (TypeError, ValueError):  # TOML cannot hold it (e.g. NaN in a key position): skip
            (d / file).write_text(json.dumps(doc, default=str))
        return argv(d)

    return prepare


def _reconstruct(d: Path) -> list[str]:
    return ["reconstruct", str(d / "project.toml"), "--method", "pseudo", "--json"]


def _sync(d: Path) -> list[str]:
    return ["sync", str(d / "project.toml"), "--out", str(d / "clocks.json"), "--json"]


def _text_case(fx: Path, rec: str, file: str, edit: Callable[[str], str], argv=_reconstruct):
    def prepare(work: Path) -> list[str]:
        d = _copy(fx / rec, work / rec)
        (d / file).write_text(edit((d / file).read_text()))
        return argv(d)

    return prepare


def _lines(fn: Callable[[list[str]], list[str]]) -> Callable[[str], str]:
    return lambda text: "\n".join(fn(text.splitlines())) + "\n"


def _cell(row: int, col: int, value: str) -> Callable[[str], str]:
    def edit(lines: list[str]) -> list[str]:
        cells = lines[row].split(",")
        cells[col % len(cells)] = value
        lines[row] = ",".join(cells)
        return lines

    return _lines(edit)


def _openpose_case(
    fx: Path, content: object, name: str = "cam_0_000000000002_keypoints.json", raw: bool = False
):
    def prepare(work: Path) -> list[str]:
        d = _copy(fx / "op", work / "op")
        (d / "cam_0" / name).write_text(content if raw else json.dumps(content))  # type: ignore[arg-type]
        return _reconstruct(d)

    return prepare


def _json_case(fx: Path, key: str, value: object):
    def prepare(work: Path) -> list[str]:
        doc = json.loads((fx / "cap.json").read_text())
        _set(doc, (key,), value)
        (work / "cap.json").write_text(json.dumps(doc))
        return ["reconstruct", str(work / "cap.json"), "--method", "pseudo", "--sequencing", "none", "--json"]

    return prepare


def _override_case(argv: list[str], override: str, program: str):
    def prepare(work: Path) -> list[str]:
        return [a.replace("{work}", str(work)) for a in argv] + [override]

    return prepare


def _dataset_case(fx: Path, damage: Callable[[Path], None]):
    def prepare(work: Path) -> list[str]:
        d = _copy(fx / "tiny", work / "tiny")
        damage(d)
        return ["verify", str(d), "--deep"]

    return prepare


def _truncate(rel: str, keep: float) -> Callable[[Path], None]:
    def damage(d: Path) -> None:
        f = d / rel
        data = f.read_bytes()
        f.write_bytes(data[: int(len(data) * keep)])

    return damage


def _write(rel: str, text: str) -> Callable[[Path], None]:
    return lambda d: (d / rel).write_text(text)


def _edit_manifest(fn: Callable[[dict], None]) -> Callable[[Path], None]:
    def damage(d: Path) -> None:
        m = json.loads((d / "manifest.json").read_text())
        fn(m)
        (d / "manifest.json").write_text(json.dumps(m))

    return damage


def build_cases(fx: Path) -> list[Case]:
    """Every replayed case, generated from the fixtures in ``fx`` by mutation."""
    return _project_cases(fx) + _detector_cases(fx) + _recipe_cases(fx) + _dataset_cases(fx)


def _project_cases(fx: Path) -> list[Case]:
    """Calibration and project fields given a wrong value or deleted."""
    cases: list[Case] = []
    add = cases.append
    cal_fields = [("cam_0", "matrix"), ("cam_0", "distortions"), ("cam_0", "rotation"), ("cam_0", "translation"),
                  ("cam_0", "size"), ("cam_0", "matrix", 0), ("cam_0", "distortions", 0), ("cam_1",), ("metadata", "units")]  # fmt: skip
    for path in cal_fields:
        for v in VALUES:
            add(Case(f"reconstruct: calibration {'.'.join(map(str, path))} = {v!r}", "gttnet",
                     _toml_case(fx, "op", "calibration.toml", path, v, _reconstruct)))  # fmt: skip
    proj_fields = [("calibration",), ("clock",), ("min_confidence",), ("calibration_units",), ("cameras",),
                   ("cameras", 0), ("cameras", 0, "name"), ("cameras", 0, "keypoints"), ("cameras", 0, "timestamps"),
                   ("skeleton",), ("skeleton", "parents"), ("skeleton", "joint_names")]  # fmt: skip
    for path in proj_fields:
        for v in VALUES:
            add(Case(f"reconstruct: project {'.'.join(map(str, path))} = {v!r}", "gttnet",
                     _toml_case(fx, "op", "project.toml", path, v, _reconstruct)))  # fmt: skip
    for path in (("clock",), ("cameras", 0, "timestamps"), ("cameras", 1, "fps")):
        for v in ("abc", math.inf, -1, "<delete>"):
            add(Case(f"sync: project {'.'.join(map(str, path))} = {v!r}", "gttnet",
                     _toml_case(fx, "op", "project.toml", path, v, _sync)))  # fmt: skip
    return cases


def _detector_cases(fx: Path) -> list[Case]:
    """Damaged OpenPose, DeepLabCut, timestamp and GTT-Net JSON files."""
    cases: list[Case] = []
    add = cases.append
    person = {"people": [{"pose_keypoints_2d": [500.0, 500.0, 0.9] * 5}]}
    op_docs: list[tuple[str, object, bool]] = [
        ("not JSON", "{people: [", True), ("binary", "\xff\xfe\x00", True), ("empty file", "", True),
        ("a list", [], False), ("people null", {"people": None}, False),
        ("keypoints strings", {"people": [{"pose_keypoints_2d": ["a"] * 15}]}, False),
        ("keypoints nested", {"people": [{"pose_keypoints_2d": [[1.0]] * 15}]}, False),
        ("keypoints 14 values", {"people": [{"pose_keypoints_2d": [1.0] * 14}]}, False),
        ("6 joints", {"people": [{"pose_keypoints_2d": [1.0] * 18}]}, False),
        ("infinite", {"people": [{"pose_keypoints_2d": [1e400, 500.0, 0.9] * 5}]}, False),
        ("-5000 px", {"people": [{"pose_keypoints_2d": [-5000.0, 500.0, 0.9] * 5}]}, False),
        ("1e300 px", {"people": [{"pose_keypoints_2d": [1e300, 500.0, 0.9] * 5}]}, False),
        ("deeply nested", "[" * 100000 + "]" * 100000, True),
    ]  # fmt: skip
    for name, doc, raw in op_docs:
        add(Case(f"reconstruct: OpenPose frame file {name}", "gttnet", _openpose_case(fx, doc, raw=raw)))
    add(
        Case(
            "reconstruct: OpenPose stray del_000001_0.json",
            "gttnet",
            _openpose_case(fx, person, "del_000001_0.json"),
        )
    )
    add(
        Case(
            "reconstruct: OpenPose duplicate frame 1",
            "gttnet",
            _openpose_case(fx, person, "cam_0_1_keypoints.json"),
        )
    )
    dlc_edits = {
        "header row dropped": _lines(lambda ls: ls[1:]),
        "coords row dropped": _lines(lambda ls: ls[:2] + ls[3:]),
        "no rows": _lines(lambda ls: ls[:3]),
        "ragged row": _lines(lambda ls: ls[:4] + [ls[4] + ",1.0"] + ls[5:]),
        "text value": _cell(4, 2, "abc"),
        "inf value": _cell(4, 2, "inf"),
        "frame inf": _cell(4, 0, "inf"),
        "frame -1": _cell(4, 0, "-1"),
        "frame 2.5": _cell(4, 0, "2.5"),
        "frames repeat": _cell(5, 0, "0"),
        "binary": lambda t: "\x00\xff" * 10,
        "-5000 px": _cell(4, 1, "-5000"),
    }
    for name, edit in dlc_edits.items():
        add(Case(f"reconstruct: DeepLabCut CSV {name}", "gttnet", _text_case(fx, "dlc", "cam_0.csv", edit)))
    ts_edits = {
        "empty": lambda t: "",
        "N/A": _cell(2, -1, "N/A"),
        "decreasing": _cell(2, -1, "-1"),
        "inf": _cell(2, -1, "inf"),
        "too short": _lines(lambda ls: ls[:2]),
        "binary": lambda t: "\x00\xff",
    }
    for name, edit in ts_edits.items():
        add(
            Case(
                f"reconstruct: timestamps {name}",
                "gttnet",
                _text_case(fx, "op", "cam_0_timestamps.csv", edit),
            )
        )
        add(
            Case(
                f"sync: timestamps {name}",
                "gttnet",
                _text_case(fx, "op", "cam_0_timestamps.csv", edit, _sync),
            )
        )
    for key in ("ray", "C", "camID", "K", "t", "limbSeq", "units", "point3D"):
        for v in ("abc", math.nan, math.inf, -1, [], [[1.0]], "<delete>"):
            add(Case(f"reconstruct: GTT-Net JSON {key} = {v!r}", "gttnet", _json_case(fx, key, v)))
    return cases


def _recipe_cases(fx: Path) -> list[Case]:
    """Out-of-range or malformed recipe overrides of generate, train and evaluate."""
    cases: list[Case] = []
    add = cases.append
    tiny = str(REPO / "recipes/gttdata/tiny.yaml")
    gen = ["generate", tiny, "--out", "{work}/data", "--no-progress"]
    for ov in ("capture.sigma_px=.inf", "capture.sigma_px=.nan", "capture.sigma_px=-1", "capture.fps_hz=0",
               "capture.fps_hz=1e9", "capture.window_s=-1", "capture.joint_drop_rate=2", "splits.0.n_samples=-1",
               "splits.0.n_samples=abc", "seed=-1", "seed=1.5", "rig.n_cameras=0", "rig.n_cameras=1",
               "capture.sigma_px={normal: [0, .inf]}", "capture.sigma_px={uniform: [3, 1]}", "shard.compression=zip",
               "splits.0.sources.0.kind=[a]", "capture=[1", "nosuchkey=1", "capture.sigma_px"):  # fmt: skip
        add(Case(f"generate: {ov}", "gttdata", _override_case(gen, ov, "gttdata")))
    train = ["train", str(REPO / "recipes/gttnet/tiny.yaml"), "--out", "{work}/run", "--device", "cpu",
             "--max-steps", "1", "--no-progress"]  # fmt: skip
    for ov in ("train.checkpoint_every=0", "train.log_every=0", "train.batch_size=0", "train.batch_size=1e9",
               "stages.0.lr=.inf", "stages.0.lr=-1", "stages.0.steps=0", "stages.0.steps=abc", "seed=-1",
               "data.num_workers=-1", "train.grad_clip=0", "stages.0.losses.nope=1", "stages.0.losses.affinity=.nan",
               "model.builder=nope", "data.sources=[]", "stages=[]", "train.steps_per_epoch=0"):  # fmt: skip
        add(Case(f"train: {ov}", "gttnet", _override_case(train, ov, "gttnet")))
    ev = ["evaluate", str(REPO / "recipes/gttnet/eval_smoke.yaml"), "--out", "{work}/eval", "--no-progress"]
    for ov in ("workers=0", "data.n_sequences=0", "seed=-1", "sequencing=[sideways]", "methods=[]",
               "sweeps.0.values=[.inf]", "data.generate=missing.yaml"):  # fmt: skip
        add(Case(f"evaluate: {ov}", "gttnet", _override_case(ev, ov, "gttnet")))
    return cases


def _dataset_cases(fx: Path) -> list[Case]:
    """A damaged shard or manifest under ``gttdata verify --deep``."""
    shard = "test/shard-00000.h5"
    dataset_damage = {
        "shard truncated": _truncate(shard, 0.5),
        "shard emptied": _truncate(shard, 0.0),
        "shard garbage": _write(shard, "not an HDF5 file"),
        "manifest garbage": _write("manifest.json", "{"),
        "manifest a list": _write("manifest.json", "[]"),
        "manifest splits null": _edit_manifest(lambda m: m.__setitem__("splits", None)),
        "manifest without splits": _edit_manifest(lambda m: m.pop("splits", None)),
    }
    return [
        Case(f"verify: {name}", "gttdata", _dataset_case(fx, damage))
        for name, damage in dataset_damage.items()
    ]


# --- running --------------------------------------------------------------------------------------------


def classify(code: int | None, output: str, exception: BaseException | None = None) -> str:
    """The outcome of a finished command (see the module docstring)."""
    if code is not None and code < 0:
        return "segfault"
    if "Traceback (most recent call last)" in output or (
        exception is not None and not isinstance(exception, SystemExit)
    ):
        return "traceback"
    if code == 0:
        return "ok"
    errors = [ln for ln in output.splitlines() if ln.startswith("Error:")]
    return "one-line" if len(errors) == 1 and "Aborted!" not in output else "multi-line"


def run_case(case: Case, work: Path, *, subprocess_mode: bool = False, timeout: float = 300) -> Result:
    """Prepare ``case`` in ``work`` (an empty folder) and run it; the command runs with ``work`` as its folder."""
    argv = case.prepare(work)
    start = time.perf_counter()
    if subprocess_mode:
        from tests._subprocess import repo_env

        proc = subprocess.run(
            [sys.executable, "-m", case.program, *argv], capture_output=True, text=True, timeout=timeout,
            env=repo_env(), cwd=work,
        )  # fmt: skip
        outcome = classify(proc.returncode, proc.stdout + proc.stderr)
        return Result(case, outcome, proc.stdout + proc.stderr, time.perf_counter() - start)
    from click.testing import CliRunner

    from gttdata.cli import main as gttdata_main
    from gttnet.cli import main as gttnet_main

    main = gttnet_main if case.program == "gttnet" else gttdata_main
    with contextlib.chdir(work):
        res = CliRunner().invoke(main, argv)
    output = res.output
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        import traceback

        output += "".join(traceback.format_exception(res.exception))
    return Result(case, classify(res.exit_code, output, res.exception), output, time.perf_counter() - start)


def replay(cases: list[Case], root: Path, *, subprocess_mode: bool = False) -> list[Result]:
    """Run every case in its own folder under ``root``."""
    out = []
    for i, case in enumerate(cases):
        work = root / f"case{i:03d}"
        work.mkdir()
        out.append(run_case(case, work, subprocess_mode=subprocess_mode))
    return out


def table(results: list[Result]) -> str:
    """A Markdown table: one row per command, the count of each outcome, and a total row."""
    rows: dict[str, dict[str, int]] = {}
    for r in results:
        rows.setdefault(r.case.command, dict.fromkeys(OUTCOMES, 0))[r.outcome] += 1
    head = "| command | cases | " + " | ".join(OUTCOMES) + " |"
    lines = [head, "|" + "---|" * (len(OUTCOMES) + 2)]
    total = dict.fromkeys(OUTCOMES, 0)
    for cmd, counts in rows.items():
        lines.append(
            f"| `{cmd}` | {sum(counts.values())} | " + " | ".join(str(counts[o]) for o in OUTCOMES) + " |"
        )
        for o in OUTCOMES:
            total[o] += counts[o]
    lines.append(f"| all | {len(results)} | " + " | ".join(str(total[o]) for o in OUTCOMES) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Build the fixtures, replay every case, print the table and the failures; exit 1 on a traceback or crash."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--subprocess", action="store_true", help="Run each case as a real process (sees segfaults)."
    )
    ap.add_argument("--every", type=int, default=1, help="Replay every N-th case only.")
    ap.add_argument("--show", action="store_true", help="Print every case's outcome and last line.")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="audit-replay-") as tmp:
        root = Path(tmp)
        fx = build_fixtures(root / "fixtures")
        cases = build_cases(fx)[:: args.every]
        start = time.perf_counter()
        results = replay(cases, root, subprocess_mode=args.subprocess)
        print(table(results))
        print(
            f"\n{len(results)} cases in {time.perf_counter() - start:.0f} s ({'subprocess' if args.subprocess else 'in process'})"
        )
        for r in results:
            if args.show or r.outcome in ("traceback", "segfault", "multi-line"):
                last = next((ln for ln in reversed(r.output.splitlines()) if ln.strip()), "")
                print(f"{r.outcome:10s} {r.case.program} {r.case.name}: {last[:200]}")
    bad = sum(r.outcome in ("traceback", "segfault") for r in results)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
