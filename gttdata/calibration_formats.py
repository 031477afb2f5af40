"""Calibration files of motion-capture systems and calibration tools that Pose2Sim converts.

Every reader returns ``(rig, units)``: a :class:`~gttdata.cameras.CameraRig` in metres whose cameras hold
``cam_from_world`` (world -> OpenCV camera: x right, y down, z along the optical axis) and the length
unit the file was written in. The unit comes from the format, never from a guess:

* **Qualisys** ``.qca.txt`` (XML): per ``cameras/camera`` (``serial``, ``model``), ``fov_video`` (``left``,
  ``top``, ``right``, ``bottom`` pixels), ``intrinsic`` (``focalLengthU/V``, ``centerPointU/V``,
  ``radialDistortion1/2``, ``tangentalDistortion1/2``, all in 1/64 pixel: divided by 64, the principal
  point then taken relative to the video window) and ``transform`` (``x``, ``y``, ``z``: the camera centre
  in world, **millimetres**; ``r11``...``r33`` read row by row give ``M``, the rotation world -> Qualisys
  camera frame). Qualisys' camera frame looks along -z with y up, so ``cam_from_world = Rx(pi) @ [M |
  -M C]``. Only video cameras (models ``Miqus Video``, ``Miqus Video UnderWater``, ``none``) are read;
  they are named by serial. This is the conversion Pose2Sim's ``calib_qca_fun`` makes.
* **Vicon** ``.xcp`` (XML): per ``Camera`` (``DEVICEID``, ``TYPE`` holding ``VIDEO``, ``SENSOR_SIZE``,
  ``PIXEL_ASPECT_RATIO``) a ``KeyFrames/KeyFrame`` with ``FOCAL_LENGTH`` (pixels, fx; fy = fx /
  aspect), ``PRINCIPAL_POINT``, ``VICON_RADIAL2`` (k1, k2 at positions 3, 4) or ``VICON_RADIAL`` (k1, k2),
  ``ORIENTATION`` (quaternion x y z w: the rotation world -> camera) and ``POSITION`` (camera centre in
  world, **millimetres**). Pose2Sim's ``calib_vicon_fun`` conversion.
* **Caliscope** ``camera_array.toml``: ``[cameras.N]`` tables (``cam_id``, ``size``, ``matrix``,
  ``distortions``, ``rotation`` as a Rodrigues vector or 3x3 matrix world -> camera, ``translation``
  world -> camera) in **metres**, Caliscope's world unit; its older ``config.toml`` (``[cam_N]`` tables
  with ``port``) likewise. Caliscope's ``camera_array_aniposelib.toml`` is the aniposelib TOML.
* **FreeMoCap** ``*camera_calibration.toml``: aniposelib's layout written with a ChArUco board measured
  in millimetres (``metadata.charuco_square_size``), so its translations are **millimetres**.
* **EasyMocap** ``intri.yml``/``extri.yml`` and **anipose / Pose2Sim** TOML: :mod:`gttdata.calibration`.

OpenCap's calibrations are pickles of numpy arrays: :func:`read_opencap` reads them with an unpickler that
builds arrays and builtin data only (any other global is refused before it runs). OptiTrack's are typed
in by hand in Pose2Sim (it converts none): :func:`refuse_unreadable` says so in one line.
"""

from __future__ import annotations

import importlib
import io
import os
import pickle
import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from gttdata.cameras import Camera, CameraRig, rotation_from_vector
from gttdata.errors import CalibrationError, RigError

__all__ = [
    "QCA_VIDEO_MODELS",
    "is_caliscope",
    "is_freemocap",
    "read_caliscope",
    "read_qca",
    "read_xcp",
    "refuse_unreadable",
    "write_qca",
    "write_xcp",
]

#: Qualisys camera models that record video (the only ones a 2-D keypoint detector ran on).
QCA_VIDEO_MODELS: tuple[str, ...] = ("Miqus Video", "Miqus Video UnderWater", "none")

_RX_PI = np.diag([1.0, -1.0, -1.0])  # rotation by pi about x: Qualisys camera frame <-> OpenCV's


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def _parse_xml(path: Path) -> ET.Element:
    try:
        return ET.fromstring(path.read_text())
    except (ET.ParseError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: not a readable XML calibration: {exc}") from exc


def _num(path: Path, el: ET.Element, key: str, where: str) -> float:
    value = el.get(key)
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise CalibrationError(f"{path}: {where} field {key!r} must be a number, found {value!r}") from None


def _nums(path: Path, el: ET.Element, key: str, where: str, n: int | None = None) -> np.ndarray:
    value = el.get(key)
    try:
        out = np.asarray([float(v) for v in (value or "").split()], dtype=np.float64)
    except ValueError:
        out = np.zeros(0)
    if out.size == 0 or (n is not None and out.size != n):
        raise CalibrationError(
            f"{path}: {where} field {key!r} must be {n or 'some'} numbers, found {value!r}"
        )
    return out


def _camera(path: Path, name: str, K, R, t, size, dist) -> Camera:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    try:
        return Camera(K=np.asarray(K, float), cam_from_world=T, image_size=size, name=name, dist=tuple(dist))
    except RigError as exc:
        raise CalibrationError(f"{path}: camera {name!r}: {exc}") from exc


def read_qca(path: str | Path) -> tuple[CameraRig, str]:
    """Read a Qualisys ``.qca.txt`` calibration (layout and frames in the module docstring).

    Returns:
        ``(rig, "mm")``: the video cameras in natural order of their serials, metres, ``cam_from_world``.

    Raises:
        CalibrationError: Unreadable XML, no video camera, or a missing or non-numeric field.
    """
    path = Path(path)
    root = _parse_xml(path)
    cams = []
    for i, cam in enumerate(root.findall("cameras/camera")):
        if cam.get("model") not in QCA_VIDEO_MODELS:
            continue
        name = str(cam.get("serial") or f"camera{i}")
        where = f"camera {name!r}"
        fov, intr, tr = cam.find("fov_video"), cam.find("intrinsic"), cam.find("transform")
        for tag, el in (("fov_video", fov), ("intrinsic", intr), ("transform", tr)):
            if el is None:
                raise CalibrationError(f"{path}: {where} has no <{tag}> element")
        assert fov is not None and intr is not None and tr is not None
        left, top = _num(path, fov, "left", where), _num(path, fov, "top", where)
        size = (
            int(round(_num(path, fov, "right", where) - left + 1)),
            int(round(_num(path, fov, "bottom", where) - top + 1)),
        )
        g = {k: _num(path, intr, k, where) / 64.0 for k in (
            "focalLengthU", "focalLengthV", "centerPointU", "centerPointV", "radialDistortion1",
            "radialDistortion2", "tangentalDistortion1", "tangentalDistortion2",
        )}  # fmt: skip
        K = [
            [g["focalLengthU"], 0.0, g["centerPointU"] - left],
            [0.0, g["focalLengthV"], g["centerPointV"] - top],
            [0.0, 0.0, 1.0],
        ]
        dist = (
            g["radialDistortion1"],
            g["radialDistortion2"],
            g["tangentalDistortion1"],
            g["tangentalDistortion2"],
        )
        M = np.array([[_num(path, tr, f"r{a}{b}", where) for b in (1, 2, 3)] for a in (1, 2, 3)])
        centre = np.array([_num(path, tr, k, where) for k in ("x", "y", "z")]) * 1e-3
        R = _RX_PI @ M
        cams.append(_camera(path, name, K, R, -R @ centre, size, dist))
    if not cams:
        raise CalibrationError(
            f"{path}: no video camera (model one of {', '.join(QCA_VIDEO_MODELS)}) in cameras/camera"
        )
    cams.sort(key=lambda c: _natural_key(c.name))
    return CameraRig(tuple(cams)), "mm"


def read_xcp(path: str | Path) -> tuple[CameraRig, str]:
    """Read a Vicon ``.xcp`` calibration (layout and frames in the module docstring).

    Returns:
        ``(rig, "mm")``: the video cameras in natural order of their device ids, metres.

    Raises:
        CalibrationError: Unreadable XML, no video camera, or a missing or malformed field.
    """
    path = Path(path)
    root = _parse_xml(path)
    cams: list[Camera] = []
    for cam in root.findall("Camera"):
        if "VIDEO" not in str(cam.get("TYPE", "")).upper():
            continue
        name = str(cam.get("DEVICEID") or cam.get("USERID") or f"camera{len(cams)}")
        where = f"Camera {name!r}"
        kf = cam.find("KeyFrames/KeyFrame")
        if kf is None:
            raise CalibrationError(f"{path}: {where} has no KeyFrames/KeyFrame element")
        w, h = _nums(path, cam, "SENSOR_SIZE", where, 2)
        fx = _num(path, kf, "FOCAL_LENGTH", where)
        fy = fx / _num(path, cam, "PIXEL_ASPECT_RATIO", where)
        cx, cy = _nums(path, kf, "PRINCIPAL_POINT", where, 2)
        if kf.get("VICON_RADIAL2") is not None:
            k = _nums(path, kf, "VICON_RADIAL2", where)
            if k.size < 5:
                raise CalibrationError(
                    f"{path}: {where} field 'VICON_RADIAL2' needs 5 numbers, found {k.size}"
                )
            k1, k2 = k[3:5]
        else:
            k1, k2 = _nums(path, kf, "VICON_RADIAL", where, 2)
        q = _nums(path, kf, "ORIENTATION", where, 4)
        if not np.isclose(np.linalg.norm(q), 1.0, atol=1e-3):
            raise CalibrationError(
                f"{path}: {where} field 'ORIENTATION' must be a unit quaternion, found {q}"
            )
        from scipy.spatial.transform import Rotation  # imported on use: 0.1-0.2 s of start-up

        R = Rotation.from_quat(q).as_matrix()
        centre = _nums(path, kf, "POSITION", where, 3) * 1e-3
        K = [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]
        cams.append(_camera(path, name, K, R, -R @ centre, (int(w), int(h)), (k1, k2, 0.0, 0.0)))
    if not cams:
        raise CalibrationError(f"{path}: no Camera with TYPE containing VIDEO")
    cams.sort(key=lambda c: _natural_key(c.name))
    return CameraRig(tuple(cams)), "mm"


def _toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: cannot parse calibration TOML: {exc}") from exc


def is_caliscope(d: dict) -> bool:
    """Whether a parsed TOML is a Caliscope camera array (``[cameras.N]`` or ``[cam_N]`` with ``port``)."""
    if isinstance(d.get("cameras"), dict):
        return True
    return any(k.startswith("cam_") and isinstance(v, dict) and "port" in v for k, v in d.items())


def is_freemocap(d: dict) -> bool:
    """Whether a parsed aniposelib TOML was written by FreeMoCap (a ChArUco square size in its metadata)."""
    meta = d.get("metadata")
    return isinstance(meta, dict) and any(k.startswith("charuco") for k in meta)


def read_caliscope(path: str | Path) -> tuple[CameraRig, str]:
    """Read a Caliscope ``camera_array.toml`` (or older ``config.toml``); translations in metres.

    Cameras without a rotation or translation (not posed yet) are left out. Names: the table's ``name``,
    else ``cam_<cam_id>`` (or ``cam_<port>``).

    Raises:
        CalibrationError: No posed camera, or a malformed field.
    """
    path = Path(path)
    d = _toml(path)
    tables = (
        {f"cameras.{k}": v for k, v in d["cameras"].items()}
        if isinstance(d.get("cameras"), dict)
        else {k: v for k, v in d.items() if k.startswith("cam_") and isinstance(v, dict)}
    )
    cams = []
    for key, tab in tables.items():
        if not isinstance(tab, dict) or tab.get("rotation") is None or tab.get("translation") is None:
            continue
        ident = tab.get("cam_id", tab.get("port", key.rsplit(".", 1)[-1]))
        name = str(tab.get("name") or f"cam_{ident}")
        try:
            rot = np.asarray(tab["rotation"], dtype=np.float64)
            R = rotation_from_vector(rot) if rot.size == 3 else rot.reshape(3, 3)
            t = np.asarray(tab["translation"], dtype=np.float64).reshape(3)
            K = np.asarray(tab["matrix"], dtype=np.float64).reshape(3, 3)
            dist = [float(v) for v in np.asarray(tab.get("distortions", [0.0] * 5), dtype=np.float64).ravel()]
            size = tuple(int(v) for v in tab["size"])
        except (KeyError, ValueError, TypeError) as exc:
            raise CalibrationError(f"{path}: [{key}] has a missing or malformed field: {exc}") from exc
        if len(size) != 2:
            raise CalibrationError(
                f"{path}: [{key}] field 'size' must be [width, height], found {tab['size']}"
            )
        cams.append(_camera(path, name, K, R, t, (size[0], size[1]), dist))
    if not cams:
        raise CalibrationError(f"{path}: no posed camera (a table with 'rotation' and 'translation')")
    cams.sort(key=lambda c: _natural_key(c.name))
    return CameraRig(tuple(cams)), "m"


#: The only globals an OpenCap calibration pickle may name: numpy's array and dtype constructors (data only).
_NUMPY_DATA = {
    (mod, name)
    for mod in (
        "numpy.core.multiarray",
        "numpy._core.multiarray",
        "numpy.core.numeric",
        "numpy._core.numeric",
        "numpy",
    )
    for name in ("_reconstruct", "scalar", "_frombuffer", "ndarray", "dtype")
} | {("_codecs", "encode")}  # protocol 2 writes an array's bytes as a latin-1 string encoded back to bytes


class _ArraysOnly(pickle.Unpickler):
    """An unpickler that builds builtin data and numpy arrays, and resolves no other global."""

    def find_class(self, module: str, name: str):  # noqa: D102 - pickle's hook
        if (module, name) not in _NUMPY_DATA:
            raise pickle.UnpicklingError(f"global {module}.{name}")
        return getattr(importlib.import_module(module), name)

    def persistent_load(self, pid):  # noqa: D102 - pickle's hook
        raise pickle.UnpicklingError("persistent id")


def _opencap_dict(path: Path) -> dict:
    try:
        data = _ArraysOnly(io.BytesIO(path.read_bytes())).load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError) as exc:
        raise CalibrationError(
            f"{path}: expected an OpenCap calibration pickle of numpy arrays, found {exc} "
            "(nothing in it was run: only numpy arrays and builtin data are read)"
        ) from None
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: expected a dict of arrays, found {type(data).__name__}")
    return data


def _opencap_array(path: Path, d: dict, key: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    if key not in d:
        raise CalibrationError(f"{path}: field '{key}': expected an array, found no such key")
    try:
        a = np.asarray(d[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(
            f"{path}: field '{key}': expected numbers, found {type(d[key]).__name__}"
        ) from None
    if shape is not None and a.size != int(np.prod(shape)):
        raise CalibrationError(
            f"{path}: field '{key}': expected {int(np.prod(shape))} numbers, found shape {a.shape}"
        )
    if not np.all(np.isfinite(a)):
        raise CalibrationError(f"{path}: field '{key}': expected finite numbers, found NaN or inf")
    return a if shape is None else a.reshape(shape)


def _opencap_files(path: Path) -> list[tuple[str, Path]]:
    """The session's camera pickles: siblings of ``path`` (named by file), or ``../*/<its name>`` (by folder)."""
    sib = sorted(
        (p for p in path.parent.iterdir() if p.suffix.lower() in (".pickle", ".pkl")),
        key=lambda p: _natural_key(p.name),
    )
    if len(sib) > 1:
        return [(p.stem, p) for p in sib]
    per_folder = sorted(path.parent.parent.glob(f"*/{path.name}"), key=lambda p: _natural_key(p.parent.name))
    return [(p.parent.name, p) for p in per_folder] or [(path.stem, path)]


def read_opencap(path: str | Path) -> tuple[CameraRig, str]:
    """Read OpenCap's per-camera calibration pickles (``cameraIntrinsicsExtrinsics.pickle``) as one rig.

    ``path`` is one camera's pickle; the rig is every pickle beside it (cameras named by file), or, in
    OpenCap's own layout (``Videos/Cam0/cameraIntrinsicsExtrinsics.pickle``, ``Cam1/...``), the file of the
    same name in each sibling folder (cameras named by folder). Each pickle is a dict of numpy arrays:
    ``intrinsicMat`` (3 x 3, pixels), ``distortion`` (k1, k2, p1, p2, k3; the first four are kept),
    ``imageSize`` (height, width), ``rotation`` (3 x 3) and ``translation`` (3, millimetres): OpenCV's
    ``cam_from_world`` in a world frame set by a vertical calibration board (y down the board, z out of
    it). The world is turned to ours (z up: ``X_ours = Rz(pi) Rx(-pi/2) X_board``), as Pose2Sim's
    conversion does. The file is read by an unpickler that builds numpy arrays and builtin data only:
    any other global (a function, a class) is refused before anything runs.

    Returns:
        ``(rig in metres, "mm")``: the unit the format fixes.

    Raises:
        CalibrationError: A pickle that names another global, is damaged, or lacks a field (one line).
    """
    path = Path(path)
    Rw = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0]]) @ np.array(
        [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]
    )  # Rz(pi) @ Rx(-pi/2): board frame -> ours
    cams = []
    for name, f in _opencap_files(path):
        d = _opencap_dict(f)
        K = _opencap_array(f, d, "intrinsicMat", (3, 3))
        dist = _opencap_array(f, d, "distortion").ravel()
        h, w = _opencap_array(f, d, "imageSize").ravel()[:2]
        R = _opencap_array(f, d, "rotation", (3, 3))
        t = _opencap_array(f, d, "translation").ravel()
        if t.size != 3 or dist.size < 4:
            raise CalibrationError(f"{f}: fields 'translation'/'distortion': expected 3 and >= 4 numbers")
        cams.append(_camera(f, name, K, R @ Rw.T, t / 1000.0, (int(round(w)), int(round(h))), dist[:4]))
    return CameraRig(tuple(cams)), "mm"


def refuse_unreadable(path: str | Path) -> None:
    """Raise one line for calibration files that are never read: OptiTrack's (Pose2Sim has them typed in).

    Raises:
        CalibrationError: Always, naming the file and what to do instead.
    """
    path = Path(path)
    raise CalibrationError(
        f"{path}: OptiTrack calibrations are not read; enter the values in a Pose2Sim/aniposelib .toml "
        "as Pose2Sim's documentation describes"
    )


def _write_atomic(path: Path, text: str) -> Path:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return path


def write_qca(rig: CameraRig, path: str | Path) -> Path:
    """Write ``rig`` (metres, ``cam_from_world``) as a Qualisys ``.qca.txt``: the inverse of :func:`read_qca`.

    Only k1, k2, p1, p2 of each camera's distortion are kept (the layout has no more).
    """
    root = ET.Element("calibration", {"source": "gttdata"})
    cams_el = ET.SubElement(root, "cameras")
    for c in rig.cameras:
        el = ET.SubElement(
            cams_el, "camera", {"serial": c.name, "model": "Miqus Video", "avg-residual": "0", "active": "1"}
        )
        w, h = c.image_size
        ET.SubElement(el, "fov_video", {"left": "0", "top": "0", "right": str(w - 1), "bottom": str(h - 1)})
        M = _RX_PI @ c.R
        tr = {k: repr(float(v)) for k, v in zip(("x", "y", "z"), c.center * 1e3, strict=True)}
        tr |= {f"r{a + 1}{b + 1}": repr(float(M[a, b])) for a in range(3) for b in range(3)}
        ET.SubElement(el, "transform", tr)
        d = list(c.dist) + [0.0] * 4
        vals = (c.K[0, 0], c.K[1, 1], c.K[0, 2], c.K[1, 2], d[0], d[1], d[2], d[3])
        keys = (
            "focalLengthU", "focalLengthV", "centerPointU", "centerPointV", "radialDistortion1",
            "radialDistortion2", "tangentalDistortion1", "tangentalDistortion2",
        )  # fmt: skip
        ET.SubElement(el, "intrinsic", {k: repr(float(v) * 64.0) for k, v in zip(keys, vals, strict=True)})
    return _write_atomic(Path(path), ET.tostring(root, encoding="unicode"))


def write_xcp(rig: CameraRig, path: str | Path) -> Path:
    """Write ``rig`` (metres) as a Vicon ``.xcp``: the inverse of :func:`read_xcp` (k1, k2 kept)."""
    from scipy.spatial.transform import Rotation

    root = ET.Element("Cameras", {"VERSION": "1.0"})
    for c in rig.cameras:
        el = ET.SubElement(
            root,
            "Camera",
            {
                "DEVICEID": c.name,
                "TYPE": "VIDEO",
                "SENSOR_SIZE": f"{c.image_size[0]} {c.image_size[1]}",
                "PIXEL_ASPECT_RATIO": repr(float(c.K[0, 0] / c.K[1, 1])),
            },
        )
        kf = ET.SubElement(ET.SubElement(el, "KeyFrames"), "KeyFrame")
        d = list(c.dist) + [0.0, 0.0]
        kf.attrib.update(
            {
                "FOCAL_LENGTH": repr(float(c.K[0, 0])),
                "PRINCIPAL_POINT": f"{float(c.K[0, 2])!r} {float(c.K[1, 2])!r}",
                "VICON_RADIAL": f"{float(d[0])!r} {float(d[1])!r}",
                "ORIENTATION": " ".join(repr(float(v)) for v in Rotation.from_matrix(c.R).as_quat()),
                "POSITION": " ".join(repr(float(v)) for v in c.center * 1e3),
                "WORLD_ERROR": "0",
            }
        )
    return _write_atomic(Path(path), ET.tostring(root, encoding="unicode"))
