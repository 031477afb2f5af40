"""Tests for the motion loaders: registry, BVH, ASF/AMC, C3D and NPZ/HDF5, on files written by the tests."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from gttdata.errors import MotionFormatError
from gttdata.mocap import available_formats, format_for_path, load_motion, register_loader
from gttdata.mocap.arrays import save_motion
from gttdata.mocap.bvh import CMU_BVH_SCALE_M
from gttdata.mocap.motion import Motion
from gttdata.skeleton import CMU31_BVH_ALIASES, CMU31_JOINTS, Skeleton, cmu31

CMU_M = 0.0254 / 0.45


def _rot(axis: str, deg: float) -> np.ndarray:
    """Right-handed rotation matrix about x, y or z, written out by hand (independent of scipy)."""
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis.upper()]


def _y_up_to_z_up(p: np.ndarray) -> np.ndarray:
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def _one_line(exc: pytest.ExceptionInfo, path: Path) -> None:
    assert "\n" not in str(exc.value) and str(path) in str(exc.value)


def test_registry_formats_suffixes_and_errors(tmp_path):
    assert {"bvh", "amc", "c3d", "npz", "hdf5"} <= set(available_formats())
    assert format_for_path("a/B.BVH") == "bvh"
    assert format_for_path("x.hdf5") == format_for_path("x.h5") == "hdf5"
    f = tmp_path / "m.xyz"
    f.write_text("")
    with pytest.raises(MotionFormatError, match="unknown motion file suffix") as e:
        load_motion(f)
    _one_line(e, f)
    with pytest.raises(MotionFormatError, match="unknown motion format 'nope'"):
        load_motion(f, fmt="nope")
    with pytest.raises(FileNotFoundError):
        load_motion(tmp_path / "missing.bvh")


def test_register_loader_decorator_dispatches(tmp_path):
    calls = []

    @register_loader("testfmt", suffixes=(".tstm",))
    def _load(path, **options):
        calls.append((Path(path).name, options))
        return Motion(np.zeros((1, 1, 3)), 30.0, Skeleton("s", ("a",), (-1,)))

    f = tmp_path / "clip.tstm"
    f.write_text("x")
    assert load_motion(f, flag=1).fps_hz == 30.0
    assert load_motion(f, fmt="TESTFMT").n_frames == 1
    assert calls == [("clip.tstm", {"flag": 1}), ("clip.tstm", {})]


def _bvh_text(joints: list[tuple], values: np.ndarray, *, frames: int | None = None, dt: str = "0.01") -> str:
    """A BVH file. ``joints``: (name, parent index, offset, channels), parents before children."""
    lines = ["HIERARCHY"]

    def emit(i: int, depth: int) -> None:
        name, parent, off, chans = joints[i]
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if parent < 0 else 'JOINT'} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {off[0]} {off[1]} {off[2]}")
        lines.append(f"{pad}  CHANNELS {len(chans)} {' '.join(chans)}")
        kids = [k for k, j in enumerate(joints) if j[1] == i]
        for k in kids:
            emit(k, depth + 1)
        if not kids:
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET 0 1 0", f"{pad}  }}"])
        lines.append(f"{pad}}}")

    for i, j in enumerate(joints):
        if j[1] < 0:
            emit(i, 0)
    lines += ["MOTION", f"Frames: {len(values) if frames is None else frames}", f"Frame Time: {dt}"]
    lines += [" ".join(f"{v:.10g}" for v in row) for row in values]
    return "\n".join(lines) + "\n"


# Root with positions interleaved with rotations, then two joints with other rotation orders.
_CHAIN = [
    (
        "Pelvis",
        -1,
        (0.5, 1.0, 0.0),
        ["Yrotation", "Xposition", "Zrotation", "Yposition", "Xrotation", "Zposition"],
    ),
    ("Knee", 0, (0.0, -4.0, 1.0), ["Xrotation", "Zrotation", "Yrotation"]),
    ("Ankle", 1, (2.0, -3.0, 0.0), ["Zrotation", "Xrotation"]),
]


def _chain_fk(values: np.ndarray) -> np.ndarray:
    """Closed-form FK of _CHAIN from hand-written matrices: R = R_first @ R_second @ R_third."""
    out = []
    for row in values:
        ry, px, rz, py, rx, pz = row[:6]
        r0 = _rot("Y", ry) @ _rot("Z", rz) @ _rot("X", rx)
        p0 = np.array([px, py, pz])
        r1 = r0 @ _rot("X", row[6]) @ _rot("Z", row[7]) @ _rot("Y", row[8])
        p1 = p0 + r0 @ np.array(_CHAIN[1][2])
        p2 = p1 + r1 @ np.array(_CHAIN[2][2])
        out.append([p0, p1, p2])
    return np.array(out)


def test_bvh_channel_orders_match_closed_form(tmp_path):
    rng = np.random.default_rng(0)
    values = rng.uniform(-170, 170, size=(6, 11))
    values[:, [1, 3, 5]] = rng.uniform(-20, 20, size=(6, 3))
    f = tmp_path / "chain.bvh"
    f.write_text(_bvh_text(_CHAIN, values))
    m = load_motion(f, scale=0.01)
    assert m.skeleton.joint_names == ("Pelvis", "Knee", "Ankle")
    assert m.skeleton.parents == (-1, 0, 1)
    assert m.skeleton.name == "chain"
    assert m.fps_hz == 100.0
    np.testing.assert_allclose(m.positions, _y_up_to_z_up(_chain_fk(values)) * 0.01, atol=1e-12)
    assert m.provenance["path"] == str(f) and m.provenance["format"] == "bvh"


def test_bvh_ninety_degrees_and_axes(tmp_path):
    joints = [
        ("A", -1, (0, 0, 0), ["Xposition", "Yposition", "Zposition", "Zrotation"]),
        ("B", 0, (1, 0, 0), []),
    ]
    f = tmp_path / "ninety.bvh"
    f.write_text(_bvh_text(joints, np.array([[0.0, 0.0, 0.0, 90.0]])))
    m = load_motion(f, scale=1.0)
    # Rz(90) turns the +x offset to +y_bvh (up), i.e. +z in the world.
    np.testing.assert_allclose(m.positions[0, 1], [0.0, 0.0, 1.0], atol=1e-12)
    m_z = load_motion(f, scale=1.0, up_axis="z")
    np.testing.assert_allclose(m_z.positions[0, 1], [0.0, 1.0, 0.0], atol=1e-12)


def _cmu_bvh(tmp_path: Path, rng: np.random.Generator) -> tuple[Path, np.ndarray, list[str]]:
    """CMU-named BVH whose file order differs from ASF order (children listed in reverse)."""
    sk = cmu31()
    order: list[int] = []

    def visit(i: int) -> None:
        order.append(i)
        for k in reversed([k for k, p in enumerate(sk.parents) if p == i]):
            visit(k)

    visit(0)
    offsets = rng.uniform(-3, 3, size=(31, 3))
    joints = []
    for i in order:
        p = sk.parents[i]
        chans = ["Xposition", "Yposition", "Zposition"] * (p < 0) + ["Zrotation", "Yrotation", "Xrotation"]
        joints.append((CMU31_BVH_ALIASES[i], order.index(p) if p >= 0 else -1, tuple(offsets[i]), chans))
    values = np.concatenate([rng.uniform(-10, 10, (3, 3)), rng.uniform(-60, 60, (3, 93))], axis=1)
    f = tmp_path / "cmu.bvh"
    f.write_text(_bvh_text(joints, values, dt=".0083333"))
    return f, order


def test_bvh_cmu_aliases_give_cmu31_in_asf_order(tmp_path):
    f, order = _cmu_bvh(tmp_path, np.random.default_rng(1))
    m = load_motion(f)
    assert m.skeleton == cmu31()
    assert m.fps_hz == 120.0 and m.provenance["scale_m_per_unit"] == pytest.approx(CMU_M) == CMU_BVH_SCALE_M
    assert order != list(range(31))
    # Same file read with the generic path: positions per name must agree after the remap.
    from gttdata.mocap.bvh import forward_kinematics, parse_bvh

    raw = _y_up_to_z_up(forward_kinematics(parse_bvh(f))) * CMU_M
    for i, alias in enumerate(CMU31_BVH_ALIASES):
        np.testing.assert_allclose(m.positions[:, i], raw[:, order.index(i)], atol=1e-12, err_msg=alias)


def test_bvh_frame_count_mismatch_warns_and_trusts_rows(tmp_path):
    f = tmp_path / "mismatch.bvh"
    f.write_text(_bvh_text(_CHAIN, np.zeros((3, 11)), frames=2))
    with pytest.warns(UserWarning, match="header says 2 frames but the file holds 3 rows"):
        m = load_motion(f, scale=0.01)
    assert m.n_frames == 3


@pytest.mark.parametrize(("unit", "per_m"), [("m", 1.0), ("cm", 100.0), ("mm", 1000.0)])
def test_bvh_auto_scale_reads_a_human_height(tmp_path, unit, per_m):
    """A 1.7 m two-joint figure written in m, cm or mm loads at 1.7 m without a scale argument."""
    joints = [
        ("Hips", -1, (0, 0, 0), ["Xposition", "Yposition", "Zposition"]),
        ("Head", 0, (0, 1.7 * per_m, 0), []),
    ]
    f = tmp_path / f"fig_{unit}.bvh"
    f.write_text(_bvh_text(joints, np.zeros((2, 3))))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = load_motion(f)
    assert m.provenance["scale_source"] == f"auto:{unit}"
    np.testing.assert_allclose(m.positions[0, 1], [0.0, 0.0, 1.7], atol=1e-12)
    assert load_motion(f, scale=2.0 / per_m).provenance["scale_source"] == "argument"


def test_bvh_auto_scale_warns_when_no_unit_gives_a_human(tmp_path):
    joints = [("Hips", -1, (0, 0, 0), ["Xposition", "Yposition", "Zposition"]), ("Head", 0, (0, 5.0, 0), [])]
    f = tmp_path / "giant.bvh"
    f.write_text(_bvh_text(joints, np.zeros((1, 3))))
    with pytest.warns(UserWarning, match="figure height 5.00 m with the guessed unit 'm'.*pass scale"):
        load_motion(f)


def _good_bvh() -> str:
    return _bvh_text(_CHAIN, np.arange(22, dtype=float).reshape(2, 11))


def _replace_last_row(text: str, new: str) -> str:
    lines = text.rstrip("\n").split("\n")
    return "\n".join(lines[:-1] + [new]) + "\n"


def _last(text: str) -> int:
    """Line number of the last line (the last motion row)."""
    return len(text.rstrip("\n").split("\n"))


_BAD_BVH = {
    "truncated hierarchy": (lambda t: t[: t.index("JOINT Ankle")], lambda t: "expected a 'MOTION' line"),
    "truncated row": (lambda t: t.rstrip("\n")[:-6] + "\n", lambda t: f"line {_last(t)}: expected 11 values, found 9"),
    "non-numeric": (lambda t: _replace_last_row(t, "1 2 3 abc 5 6 7 8 9 10 11"), lambda t: f"line {_last(t)}: column 4 must be a number, found 'abc'"),
    "nan": (lambda t: _replace_last_row(t, "1 2 3 4 nan 6 7 8 9 10 11"), lambda t: f"line {_last(t)}: column 5 must be finite, found 'nan'"),
    "inf offset": (lambda t: t.replace("OFFSET 2.0 -3.0 0.0", "OFFSET 2.0 inf 0.0"), lambda t: "OFFSET of Ankle must be finite"),
    "unknown channel": (lambda t: t.replace("Zrotation Xrotation", "Zrotation Wrotation"), lambda t: "found 'Wrotation'"),
    "duplicate joint": (lambda t: t.replace("JOINT Ankle", "JOINT Knee"), lambda t: "joint name 'Knee' is used twice"),
    "zero frames": (lambda t: t[: t.index("Frames:")] + "Frames: 0\nFrame Time: 0.01\n", lambda t: "zero frames"),
    "bad frame time": (lambda t: t.replace("Frame Time: 0.01", "Frame Time: -1"), lambda t: "Frame Time must be > 0"),
    "missing brace": (lambda t: t.replace("JOINT Knee\n  {", "JOINT Knee\n"), lambda t: r"expected '\{', found 'OFFSET'"),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(_BAD_BVH))
def test_bvh_malformed_is_one_line(tmp_path, case):
    edit, match = _BAD_BVH[case]
    f = tmp_path / "bad.bvh"
    text = edit(_good_bvh())
    f.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(MotionFormatError, match=match(text)) as e:
            load_motion(f)
    _one_line(e, f)


def _write_asf(
    path: Path, bones: list[dict], hierarchy: dict[str, list[str]], *, length: float = 0.45
) -> None:
    """An ASF file. Each bone: name, direction (3), length, axis (3), optional order and dof."""
    out = [":version 1.10", ":name VICON", ":units", "  mass 1.0", f"  length {length}", "  angle deg"]
    out += [":documentation", "  written by the test suite"]
    out += [":root", "   order TX TY TZ RX RY RZ", "   axis XYZ", "   position 0 0 0", "   orientation 0 0 0"]
    out.append(":bonedata")
    for i, b in enumerate(bones, start=1):
        out += ["  begin", f"     id {i}", f"     name {b['name']}"]
        out.append("     direction " + " ".join(f"{v:.10g}" for v in b["direction"]))
        out.append(f"     length {b['length']:.10g}")
        out.append("     axis " + " ".join(f"{v:.10g}" for v in b["axis"]) + f" {b.get('order', 'XYZ')}")
        if b.get("dof"):
            out.append("     dof " + " ".join(b["dof"]))
            out.append("     limits " + "\n            ".join("(-180.0 180.0)" for _ in b["dof"]))
        out.append("  end")
    out += [":hierarchy", "  begin"] + [f"    {p} {' '.join(c)}" for p, c in hierarchy.items()] + ["  end"]
    path.write_text("\n".join(out) + "\n")


def _write_amc(path: Path, frames: list[dict[str, list[float]]], *, radians: bool = False) -> None:
    out = ["# AMC written by the test suite", ":FULLY-SPECIFIED", ":RADIANS" if radians else ":DEGREES"]
    for t, frame in enumerate(frames, start=1):
        out.append(str(t))
        out += [
            f"{name} " + " ".join(f"{v:.10g}" if isinstance(v, float | int) else str(v) for v in vals)
            for name, vals in frame.items()
        ]
    path.write_text("\n".join(out) + "\n")


_TWO_BONES = [
    {"name": "a", "direction": (1, 0, 0), "length": 2.0, "axis": (0, 0, 90), "dof": ("rx", "ry", "rz")},
    {"name": "b", "direction": (0, 3, 4), "length": 5.0, "axis": (30, 0, 0), "dof": ("rx",)},
]


def _two_bone_files(tmp_path: Path, frames: list[dict], **kw) -> Path:
    _write_asf(tmp_path / "07.asf", _TWO_BONES, {"root": ["a"], "a": ["b"]})
    _write_amc(tmp_path / "07_01.amc", frames, **kw)
    return tmp_path / "07_01.amc"


def test_asfamc_zero_pose_gives_offsets(tmp_path):
    zero = {"root": [1.0, 2.0, 3.0, 0, 0, 0], "a": [0, 0, 0], "b": [0]}
    amc = _two_bone_files(tmp_path, [zero])
    m = load_motion(amc, joints_at="end")
    ends = np.array([[1.0, 2.0, 3.0], [3.0, 2.0, 3.0], [3.0, 5.0, 7.0]]) * CMU_M
    np.testing.assert_allclose(m.positions[0], _y_up_to_z_up(ends), atol=1e-12)
    starts = load_motion(amc)  # default: each joint where its bone starts, as in CMU BVH files
    np.testing.assert_allclose(starts.positions[0], _y_up_to_z_up(ends[[0, 0, 1]]), atol=1e-12)
    assert m.skeleton.joint_names == ("root", "a", "b") and m.skeleton.parents == (-1, 0, 1)
    assert m.fps_hz == 120.0 and m.provenance["format"] == "amc"
    assert m.provenance["asf_path"] == str(tmp_path / "07.asf")


def test_asfamc_ninety_degrees_about_the_bone_axis(tmp_path):
    # Bone a has axis (0, 0, 90): its local x is the world y, so rx = 90 rotates about world y,
    # taking its +x direction to -z. Bone b (dof rx about its own x = world x, tilted 30 deg by C
    # only in the frame, which C M C^-1 cancels at rx = 0) then hangs off a's end, rotated with a.
    frames = [{"root": [0, 0, 0, 0, 0, 0], "a": [90, 0, 0], "b": [0]}]
    m = load_motion(_two_bone_files(tmp_path, frames), up_axis="z", joints_at="end")
    a_end = np.array([0.0, 0.0, -2.0])
    b_end = a_end + _rot("Y", 90) @ np.array([0.0, 3.0, 4.0])
    np.testing.assert_allclose(m.positions[0, 1:] / CMU_M, [a_end, b_end], atol=1e-12)


def test_asfamc_radians_root_rotation_and_units(tmp_path):
    frames = [{"root": [0, 0, 0, 0, np.pi / 2, 0], "a": [0, 0, 0], "b": [0]}]
    amc = _two_bone_files(tmp_path, frames, radians=True)
    _write_asf(tmp_path / "07.asf", _TWO_BONES, {"root": ["a"], "a": ["b"]}, length=1.0)
    m = load_motion(amc, up_axis="z", joints_at="end")
    # Root Ry(90) maps +x to -z; units length 1.0 means inches.
    np.testing.assert_allclose(m.positions[0, 1], [0.0, 0.0, -2.0 * 0.0254], atol=1e-9)


def test_asfamc_and_bvh_agree_on_the_same_motion(tmp_path):
    # The BVH twin of an ASF/AMC clip has local rotations C M C^-1 (as ZYX Euler angles) and
    # offsets length * direction: both loaders must then put every joint at the same point.
    from scipy.spatial.transform import Rotation

    bones = _TWO_BONES + [{"name": "c", "direction": (0, 1, 0), "length": 1.0, "axis": (0, 0, 0)}]
    _write_asf(tmp_path / "07.asf", bones, {"root": ["a"], "a": ["b"], "b": ["c"]})
    rng = np.random.default_rng(5)
    amc = rng.uniform(-80, 80, size=(4, 10))
    _write_amc(tmp_path / "07_01.amc", [{"root": r[:6], "a": r[6:9], "b": r[9:]} for r in amc])
    rows = []
    for r in amc:
        local = [Rotation.from_euler("xyz", r[3:6], degrees=True)]  # root axis XYZ, orientation 0
        for b, m in ((_TWO_BONES[0], Rotation.from_euler("xyz", r[6:9], degrees=True)),
                     (_TWO_BONES[1], Rotation.from_euler("x", r[9:], degrees=True))):  # fmt: skip
            C = Rotation.from_euler(b.get("order", "XYZ").lower(), b["axis"], degrees=True)
            local.append(C * m * C.inv())
        rows.append(np.concatenate([r[:3]] + [q.as_euler("ZYX", degrees=True) for q in local]))
    zyx = ["Zrotation", "Yrotation", "Xrotation"]
    joints = [("R", -1, (0, 0, 0), ["Xposition", "Yposition", "Zposition", *zyx]), ("A", 0, (0, 0, 0), zyx),
              ("B", 1, (2.0, 0, 0), zyx), ("C", 2, (0, 3.0, 4.0), [])]  # fmt: skip
    (tmp_path / "twin.bvh").write_text(_bvh_text(joints, np.array(rows)))
    from_bvh = load_motion(tmp_path / "twin.bvh", scale=CMU_M)
    from_amc = load_motion(tmp_path / "07_01.amc")
    np.testing.assert_allclose(from_amc.positions, from_bvh.positions, atol=1e-9)


def test_asfamc_cmu_names_give_cmu31(tmp_path):
    sk = cmu31()
    rng = np.random.default_rng(3)
    bones = [
        {
            "name": n,
            "direction": rng.normal(size=3),
            "length": 1.0 + i / 10,
            "axis": (0, 0, 0),
            "dof": ("rx", "ry", "rz"),
        }
        for i, n in enumerate(CMU31_JOINTS[1:], start=1)
    ]
    hierarchy: dict[str, list[str]] = {}
    for i, p in enumerate(sk.parents):
        if p >= 0:
            hierarchy.setdefault(CMU31_JOINTS[p], []).append(CMU31_JOINTS[i])
    _write_asf(tmp_path / "subj.asf", bones, hierarchy)
    frame = {"root": [0.0] * 6} | {n: [0.0, 0.0, 0.0] for n in CMU31_JOINTS[1:]}
    _write_amc(tmp_path / "clip.amc", [frame, frame])
    m = load_motion(tmp_path / "clip.amc", asf_path=tmp_path / "subj.asf", joints_at="end")
    assert m.skeleton == cmu31() and m.n_frames == 2
    starts = load_motion(tmp_path / "clip.amc", asf_path=tmp_path / "subj.asf")
    np.testing.assert_allclose(starts.positions[:, 1], starts.positions[:, 0])  # lhipjoint starts at root
    np.testing.assert_allclose(starts.positions[:, 2], m.positions[:, 1])  # lfemur starts at lhipjoint's end
    lengths = m.bone_lengths()[0] / CMU_M
    np.testing.assert_allclose(lengths, [1.0 + (c - 0) / 10 for c in m.skeleton.bones[:, 0]], rtol=1e-12)


_OK_FRAME = {"root": [0, 0, 0, 0, 0, 0], "a": [0, 0, 0], "b": [0]}
_BAD_AMC = {
    "unknown joint": ([_OK_FRAME | {"c": [1.0]}], "unknown joint 'c'"),
    "value count": ([{"root": [0] * 6, "a": [0, 0], "b": [0]}], "a expects 3 values, found 2"),
    "non-numeric": ([{"root": [0] * 6, "a": [0, "x", 0], "b": [0]}], "a values must be numbers"),
    "nan": ([{"root": [0] * 6, "a": [0, float("nan"), 0], "b": [0]}], "a values must be finite"),
    "truncated frame": ([_OK_FRAME, {"root": [0] * 6, "a": [0, 0, 0]}], "frame 2: joint 'b' has no values"),
    "zero frames": ([], "zero frames"),
}


@pytest.mark.parametrize("case", sorted(_BAD_AMC))
def test_amc_malformed_is_one_line(tmp_path, case):
    frames, match = _BAD_AMC[case]
    amc = _two_bone_files(tmp_path, frames)
    with pytest.raises(MotionFormatError, match=match) as e:
        load_motion(amc)
    _one_line(e, amc)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: t[: t.index(":hierarchy")], "expected an ':hierarchy' section"),
        (lambda t: t.replace("root a", "root a zz"), "hierarchy names unknown bone 'zz'"),
        (lambda t: t.replace("length 5", "length five"), "length must be numbers"),
        (lambda t: t.replace("a b\n", "a b\n    b a\n"), "reaches bone 'a' twice"),
    ],
)
def test_asf_malformed_is_one_line(tmp_path, edit, match):
    amc = _two_bone_files(tmp_path, [_OK_FRAME])
    asf = tmp_path / "07.asf"
    asf.write_text(edit(asf.read_text()))
    with pytest.raises(MotionFormatError, match=match) as e:
        load_motion(amc)
    _one_line(e, asf)


def test_amc_without_asf_names_the_fix(tmp_path):
    _write_amc(tmp_path / "x.amc", [_OK_FRAME])
    with pytest.raises(MotionFormatError, match="pass asf_path"):
        load_motion(tmp_path / "x.amc")


# -------------------------------------------------------------------------------------------------- C3D


def _write_c3d(
    path: Path, xyz: np.ndarray, residual: np.ndarray, labels: list[str], *, units="mm", rate=100.0
):
    import c3d

    w = c3d.Writer(point_rate=rate, point_units=f"{units:<4}")
    w.set_point_labels(labels)
    for t in range(xyz.shape[0]):
        pts = np.zeros((xyz.shape[1], 5), dtype=np.float32)
        pts[:, :3], pts[:, 3] = xyz[t], residual[t]
        w.add_frames([(pts, np.zeros((0, 0), dtype=np.float32))])
    with path.open("wb") as h, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w.write(h)


def _c3d_scene(T: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """Three markers, y-up, mm: a head marker 1700 mm up moving along x, two feet, one never seen."""
    t = np.arange(T, dtype=float)
    xyz = np.zeros((T, 4, 3))
    xyz[:, 0] = np.stack([10 * t, 1700 + 0 * t, 5 * t], axis=1)
    xyz[:, 1] = [100.0, 50.0, 0.0]
    xyz[:, 2] = [-100.0, 50.0, 0.0]
    residual = np.zeros((T, 4))
    residual[:, 3] = -1.0
    residual[2:4, 0] = -1.0  # a gap in the head marker, filled linearly
    xyz[2:4, 0] = 0.0
    return xyz, residual


def test_c3d_round_trip_fills_gaps_and_drops_unseen(tmp_path):
    xyz, res = _c3d_scene()
    f = tmp_path / "trial.c3d"
    _write_c3d(f, xyz, res, ["Subj:HEAD", "Subj:LTOE", "Subj:RTOE", "Subj:GONE"])
    with pytest.warns(UserWarning, match="dropped: Subj:GONE"):
        m = load_motion(f)
    assert m.skeleton.joint_names == ("HEAD", "LTOE", "RTOE")
    assert m.skeleton.parents == (-1, -1, -1)
    assert m.skeleton.mirror == (0, 2, 1)
    assert m.fps_hz == 100.0 and m.n_frames == 6
    assert m.provenance["up_axis"] == "y" and m.provenance["missing_samples_filled"] == 2
    t = np.arange(6.0)
    head = np.stack([10 * t, 1700 + 0 * t, 5 * t], axis=1)  # linear in time, so the fill is exact
    np.testing.assert_allclose(m.positions[:, 0], _y_up_to_z_up(head) / 1000, atol=1e-6)
    np.testing.assert_allclose(m.positions[0, 1], [0.1, 0.0, 0.05], atol=1e-6)


def test_c3d_units_and_explicit_up_axis(tmp_path):
    xyz, res = _c3d_scene()
    f = tmp_path / "cm.c3d"
    _write_c3d(f, xyz[:, :3], res[:, :3], ["A", "B", "C"], units="cm")
    m = load_motion(f, up_axis="z")
    np.testing.assert_allclose(m.positions[0, 1], [1.0, 0.5, 0.0], atol=1e-6)


def test_c3d_malformed(tmp_path):
    f = tmp_path / "junk.c3d"
    f.write_bytes(b"\x00" * 10)
    with pytest.raises(MotionFormatError, match="not a readable C3D file") as e:
        load_motion(f)
    _one_line(e, f)
    xyz, res = _c3d_scene()
    res[:] = -1.0
    g = tmp_path / "empty.c3d"
    _write_c3d(g, xyz, res, ["A", "B", "C", "D"])
    with pytest.raises(MotionFormatError, match="every marker is missing") as e:
        load_motion(g)
    _one_line(e, g)
    xyz, res = _c3d_scene()
    u = tmp_path / "feet.c3d"
    _write_c3d(u, xyz[:, :3], res[:, :3], ["A", "B", "C"], units="ft")
    with pytest.raises(MotionFormatError, match="POINT:UNITS must be one of .* found 'ft'") as e:
        load_motion(u)
    _one_line(e, u)


def test_c3d_nan_samples_are_missing_and_filled(tmp_path):
    # The c3d package reads non-finite coordinates as invalid samples (residual -1), so they are
    # gaps to fill, not errors.
    xyz, res = _c3d_scene()
    xyz[1, 1] = [np.nan, np.inf, 0.0]
    f = tmp_path / "nan.c3d"
    _write_c3d(f, xyz[:, :3], res[:, :3], ["A", "B", "C"])
    m = load_motion(f)
    assert m.provenance["missing_samples_filled"] == 3
    np.testing.assert_allclose(m.positions[:, 1], m.positions[:1, 1].repeat(6, 0), atol=1e-7)


# --------------------------------------------------------------------------------------------- NPZ/HDF5


@pytest.mark.parametrize("suffix", [".npz", ".h5", ".hdf5"])
@pytest.mark.parametrize("skeleton", [cmu31(), Skeleton("toy", ("hips", "lknee", "rknee"), (-1, 0, 0))])
def test_arrays_round_trip(tmp_path, suffix, skeleton):
    rng = np.random.default_rng(4)
    m = Motion(rng.normal(size=(7, skeleton.n_joints, 3)), 60.0, skeleton, name="clip")
    f = save_motion(m, tmp_path / f"clip{suffix}")
    back = load_motion(f)
    np.testing.assert_array_equal(back.positions, m.positions)
    assert back.fps_hz == 60.0 and back.skeleton == skeleton and back.name == "clip"
    assert back.provenance["path"] == str(f)
    assert not list(tmp_path.glob("*.tmp"))


def test_arrays_units_mm(tmp_path):
    f = tmp_path / "mm.npz"
    np.savez(
        f, positions=np.ones((2, 1, 3)) * 1500.0, fps_hz=30.0, joint_names=["a"], parents=[-1], units="mm"
    )
    np.testing.assert_allclose(load_motion(f).positions, 1.5)


_GOOD_FIELDS = {
    "positions": np.zeros((2, 2, 3)),
    "fps_hz": 30.0,
    "joint_names": ["a", "b"],
    "parents": [-1, 0],
}
_BAD_FIELDS = {
    "missing field": ({"fps_hz": None}, "field 'fps_hz' is missing"),
    "shape": ({"positions": np.zeros((2, 2))}, r"must have shape \(T, J, 3\), found \(2, 2\)"),
    "zero frames": ({"positions": np.zeros((0, 2, 3))}, "zero frames"),
    "nan": ({"positions": np.full((2, 2, 3), np.nan)}, "must be finite"),
    "inf": ({"positions": np.full((2, 2, 3), np.inf)}, "must be finite"),
    "fps": ({"fps_hz": -1.0}, "field 'fps_hz' must be > 0"),
    "non-numeric": (
        {"positions": np.array([["a"] * 3] * 2).reshape(1, 2, 3)},
        "field 'positions' must be numeric",
    ),
    "unknown joint": ({"parents": [-1, 5]}, "parent of joint 1"),
    "length": ({"joint_names": ["a"]}, "must have length J = 2"),
    "units": ({"units": "furlong"}, "field 'units' must be one of"),
}


@pytest.mark.parametrize("suffix", [".npz", ".h5"])
@pytest.mark.parametrize("case", sorted(_BAD_FIELDS))
def test_arrays_malformed_is_one_line(tmp_path, suffix, case):
    import h5py

    change, match = _BAD_FIELDS[case]
    fields = {k: v for k, v in (_GOOD_FIELDS | change).items() if v is not None}
    f = tmp_path / f"bad{suffix}"
    if suffix == ".npz":
        np.savez(f, **fields)
    else:
        with h5py.File(f, "w") as h:
            for k, v in fields.items():
                a = np.asarray(v)
                if a.dtype.kind == "U":  # h5py stores text as variable-length strings
                    a = a.astype(object)
                h.create_dataset(k, data=a, dtype=h5py.string_dtype() if a.dtype == object else None)
    with pytest.raises(MotionFormatError, match=match) as e:
        load_motion(f)
    _one_line(e, f)


def test_arrays_truncated_files(tmp_path):
    for suffix in (".npz", ".h5"):
        good = save_motion(
            Motion(np.zeros((3, 1, 3)), 30.0, Skeleton("s", ("a",), (-1,))), tmp_path / f"g{suffix}"
        )
        bad = tmp_path / f"t{suffix}"
        bad.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
        with pytest.raises(MotionFormatError, match="not a readable") as e:
            load_motion(bad)
        _one_line(e, bad)
