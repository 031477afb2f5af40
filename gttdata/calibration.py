"""Calibration files of other tools, with explicit length units, lens distortion and a plausibility check.

Two layouts are read into a :class:`gttdata.cameras.CameraRig` (metres, ``cam_from_world``):

* **aniposelib / Pose2Sim TOML**: one table per camera with ``name``, ``size``, ``matrix``,
  ``distortions``, ``rotation`` (Rodrigues vector, world→camera) and ``translation`` (world→camera, in
  the calibration's length unit). The unit is taken from ``metadata.units`` when the file states it,
  else from ``units=`` (``--calibration-units``), else detected: a rig whose cameras are more than
  50 units apart on average was calibrated in millimetres (no real capture volume is 50 m wide), one
  below that in metres. The detection is logged, never silent.
* **EasyMocap / OpenCV** ``intri.yml`` + ``extri.yml`` (OpenCV FileStorage): ``names``, ``K_<name>``,
  ``dist_<name>`` and ``R_<name>`` (Rodrigues) or ``Rot_<name>`` (matrix) with ``T_<name>``. EasyMocap
  works in metres; ``units=`` overrides. Image sizes are read from ``H_<name>``/``W_<name>`` when
  present, else taken as twice the principal point.

:func:`check_rig` returns a one-line warning for a rig no real capture has: camera centres kilometres
from the scene, or cameras that have the scene behind them. :func:`undistort_points` maps detected
pixels to the pinhole image of the same intrinsics with OpenCV's ``undistortPoints``.
"""

from __future__ import annotations

import logging
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, overload

import numpy as np

from gttdata.calibration_formats import is_freemocap
from gttdata.cameras import Camera, CameraRig
from gttdata.errors import CalibrationError, RigError

if TYPE_CHECKING:  # OpenCV is imported where it is used: 0.05-0.1 s of start-up that most runs never need
    import cv2

__all__ = [
    "CALIBRATION_UNITS",
    "DISTORTION_NAMES",
    "MAX_DISTORTION",
    "check_distortion",
    "check_rig",
    "distort_points",
    "load_calibration",
    "read_easymocap",
    "read_toml_calibration",
    "save_calibration",
    "undistort_points",
]

log = logging.getLogger(__name__)

#: Length units a calibration may be written in, in metres.
CALIBRATION_UNITS: dict[str, float] = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}

#: Mean distance between camera centres above which an unlabelled calibration is read as millimetres.
MM_DETECT_SPREAD = 50.0


def _centres(rig: CameraRig) -> np.ndarray:
    return np.stack([c.center for c in rig.cameras])


def _spread(centres: np.ndarray) -> float:
    """Mean distance between camera centres (of the centres from their mean with one camera)."""
    if centres.shape[0] < 2:
        return float(np.linalg.norm(centres[0]))
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    return float(d.sum() / (centres.shape[0] * (centres.shape[0] - 1)))


def _scaled(rig: CameraRig, scale: float) -> CameraRig:
    cams = []
    for c in rig.cameras:
        T = c.cam_from_world.copy()
        T[:3, 3] *= scale
        cams.append(Camera(K=c.K, cam_from_world=T, image_size=c.image_size, name=c.name, dist=c.dist))
    return CameraRig(tuple(cams))


def _scene_point(rig: CameraRig) -> np.ndarray:
    """Least-squares closest point to all optical axes, world, shape ``(3,)``."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    for c in rig.cameras:
        d = c.R[2]  # optical axis in world
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ c.center
    if np.linalg.cond(A) > 1e8:  # parallel axes: the centres' mean pushed one metre along the mean axis
        return _centres(rig).mean(0) + np.mean([c.R[2] for c in rig.cameras], axis=0)
    return np.linalg.solve(A, b)


def check_rig(rig: CameraRig, *, units: str = "m", source: str = "calibration") -> str | None:
    """A one-line warning for an implausible rig (in metres), or None when it looks like a real capture.

    Flags camera centres more than 1 km from the scene (a millimetre file read as metres), a rig
    smaller than 5 cm (a metre file read as millimetres), and cameras whose optical axis points away
    from the scene point the axes converge on.
    """
    centres = _centres(rig)
    spread = _spread(centres)
    far = float(np.max(np.linalg.norm(centres, axis=1)))
    if far > 1000.0 or spread > 1000.0:
        hint = (
            "is the calibration in millimetres? pass --calibration-units mm"
            if units != "mm"
            else ("check the translations")
        )
        return f"{source}: camera centres are up to {far / 1000:.1f} km from the origin ({spread:.0f} m apart); {hint}"
    if len(rig) > 1 and spread < 0.05:
        hint = (
            "is the calibration in metres? pass --calibration-units m"
            if units != "m"
            else ("check the translations")
        )
        return f"{source}: cameras are only {spread * 1000:.1f} mm apart; {hint}"
    if len(rig) > 1:
        p = _scene_point(rig)
        behind = [c.name for c in rig.cameras if float(c.R[2] @ (p - c.center)) <= 0]
        if behind:
            return (
                f"{source}: camera(s) {', '.join(behind)} face away from the scene the other axes meet at "
                f"{np.round(p, 2).tolist()} m; check the rotation convention (world->camera expected) and units"
            )
    return None


#: OpenCV's distortion coefficients in order (``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]``).
DISTORTION_NAMES: tuple[str, ...] = (
    "k1",
    "k2",
    "p1",
    "p2",
    "k3",
    "k4",
    "k5",
    "k6",
    "s1",
    "s2",
    "s3",
    "s4",
    "tx",
    "ty",
)

#: Numbers of distortion coefficients OpenCV's model takes (0: no distortion).
DISTORTION_COUNTS: tuple[int, ...] = (0, 4, 5, 8, 12, 14)

#: Largest accepted magnitude of a distortion coefficient. Real lenses have |k1| of order 0.01-1 and the
#: rational model's k1..k6 reach tens; 100 and beyond is a unit or column mistake (k1 = 1e6 would fold
#: the image onto itself), so such a calibration is refused rather than used.
MAX_DISTORTION = 100.0


def check_distortion(rig: CameraRig, source: str | Path) -> None:
    """Refuse absurd lens distortion (beyond :data:`MAX_DISTORTION`) or a count OpenCV cannot use.

    A non-finite coefficient is left to :meth:`gttdata.recording.Recording.view`, which leaves that camera
    out with a warning (no detection of it can be undistorted).

    Raises:
        CalibrationError: One line naming ``source``, the camera and the coefficient.
    """
    for cam in rig.cameras:
        dist = np.asarray(cam.dist, dtype=np.float64)
        if dist.size not in DISTORTION_COUNTS:
            raise CalibrationError(
                f"{source}: camera {cam.name!r}: expected 0, 4, 5, 8, 12 or 14 distortion coefficients "
                f"(OpenCV's model), found {dist.size}"
            )
        bad = np.flatnonzero(np.isfinite(dist) & (np.abs(dist) > MAX_DISTORTION))
        if bad.size:
            i = int(bad[0])
            name = DISTORTION_NAMES[i] if i < len(DISTORTION_NAMES) else f"#{i}"
            raise CalibrationError(
                f"{source}: camera {cam.name!r}: distortion coefficient {name} (position {i}) must have "
                f"magnitude <= {MAX_DISTORTION:g}, found {dist[i]:g}"
            )


def read_toml_calibration(path: str | Path, *, units: str | None = None) -> tuple[CameraRig, str]:
    """Read an aniposelib / Pose2Sim TOML calibration; returns the rig in metres and the unit used.

    Args:
        path: The ``.toml`` file.
        units: Length unit of the translations (key of :data:`CALIBRATION_UNITS`); None: the file's
            ``metadata.units``, else detected from the rig's size.

    Raises:
        CalibrationError: Unparseable file, a missing field, or a unit that disagrees with the file.
    """
    path = Path(path)
    try:
        d = tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationError(f"{path}: cannot parse calibration TOML: {exc}") from exc
    try:
        rig = CameraRig.from_dict(d, source=str(path))
    except RigError as exc:
        raise CalibrationError(str(exc)) from exc
    meta = d.get("metadata")
    stated = meta.get("units") if isinstance(meta, dict) else None
    if stated is not None and (not isinstance(stated, str) or stated not in CALIBRATION_UNITS):
        raise CalibrationError(
            f"{path}: field 'metadata.units' must be one of {', '.join(CALIBRATION_UNITS)}, found {stated!r}"
        )
    if units is not None and units not in CALIBRATION_UNITS:
        raise CalibrationError(
            f"calibration units must be one of {', '.join(CALIBRATION_UNITS)}, got {units!r}"
        )
    if units is not None and stated is not None and units != stated:
        raise CalibrationError(f"{path}: field 'metadata.units' says {stated!r} but {units!r} was given")
    if stated is None and is_freemocap(d):  # FreeMoCap measures its ChArUco board in millimetres
        stated = "mm"
    if units is None and stated is None:
        spread = _spread(_centres(rig))
        units = "mm" if spread > MM_DETECT_SPREAD else "m"
        log.warning(
            "%s: no metadata.units; cameras are %.4g units apart on average, read as %s "
            "(pass --calibration-units to override)",
            path,
            spread,
            units,
        )
    resolved = units or stated
    assert resolved is not None  # detected above when neither was given
    return _scaled(rig, CALIBRATION_UNITS[resolved]), resolved


@overload
def _fs_mat(fs: cv2.FileStorage, key: str, path: Path) -> np.ndarray: ...
@overload
def _fs_mat(fs: cv2.FileStorage, key: str, path: Path, required: bool) -> np.ndarray | None: ...
def _fs_mat(fs: cv2.FileStorage, key: str, path: Path, required: bool = True) -> np.ndarray | None:
    """Matrix (or scalar, as a 1-vector) at ``key`` of an OpenCV YAML file; None if absent and not required."""
    node = fs.getNode(key)
    if node.empty():
        if required:
            raise CalibrationError(f"{path}: field {key!r} is missing")
        return None
    if node.isSeq():
        return np.asarray([node.at(i).real() for i in range(node.size())], dtype=np.float64)
    if node.isInt() or node.isReal():
        return np.asarray([node.real()], dtype=np.float64)
    if not _fs_matrix_ok(node):  # OpenCV aborts the process on a malformed !!opencv-matrix
        raise CalibrationError(
            f"{path}: field {key!r}: expected a number, a list or an !!opencv-matrix with rows, cols, dt "
            "and rows x cols data values"
        )
    return np.asarray(node.mat(), dtype=np.float64)


def _fs_matrix_ok(node: cv2.FileNode) -> bool:
    """Whether ``node`` is an ``!!opencv-matrix`` OpenCV can read (a malformed one aborts the process)."""
    if not node.isMap():
        return False
    rows, cols, dt, data = (node.getNode(k) for k in ("rows", "cols", "dt", "data"))
    if not (rows.isInt() and cols.isInt() and dt.isString() and data.isSeq()):
        return False
    r, c = int(rows.real()), int(cols.real())
    numbers = all(data.at(i).isInt() or data.at(i).isReal() for i in range(data.size()))
    return (
        0 <= r < 10**6
        and 0 <= c < 10**6
        and data.size() == r * c
        and dt.string() in tuple("ucwsifd")
        and numbers
    )


def _cv_message(exc: BaseException) -> str:
    """OpenCV's (multi-line) error message in one line; a ``SystemError`` wrapper gives its cause's."""
    inner = exc.__cause__ or exc.__context__ if isinstance(exc, SystemError) else None
    return " ".join(str(inner or exc).split())


def _fs_open(path: Path) -> cv2.FileStorage:
    """An OpenCV FileStorage open for reading; a YAML syntax error is one line naming the file."""
    import cv2

    try:
        return cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        raise CalibrationError(f"{path}: OpenCV cannot parse this YAML file: {_cv_message(exc)}") from exc


def _fs_names(fs: cv2.FileStorage, path: Path) -> list[str]:
    node = fs.getNode("names")
    if node.empty() or not node.isSeq():
        raise CalibrationError(f"{path}: field 'names' (a list of camera names) is missing")
    return [node.at(i).string() or str(int(node.at(i).real())) for i in range(node.size())]


def _fs_sized(fs: cv2.FileStorage, key: str, path: Path, sizes: tuple[int, ...], required: bool = True):
    """:func:`_fs_mat` checked to hold one of ``sizes`` finite numbers (None when absent and not required)."""
    m = _fs_mat(fs, key, path, required)
    if m is None:
        return None
    if m.size not in sizes or not np.all(np.isfinite(m)):
        want = " or ".join(str(n) for n in sizes)
        raise CalibrationError(
            f"{path}: field {key!r}: expected {want} finite numbers, found {m.ravel()[:9].tolist()}"
        )
    return m


def _easymocap_cameras(
    fi: cv2.FileStorage, fe: cv2.FileStorage, intri: Path, extri: Path, scale: float
) -> list:
    """The cameras of an opened EasyMocap ``intri.yml`` / ``extri.yml`` pair (translations times ``scale``)."""
    import cv2

    names = _fs_names(fi, intri)
    cams = []
    for n in names:
        K = _fs_sized(fi, f"K_{n}", intri, (9,)).reshape(3, 3)
        dist = _fs_sized(fi, f"dist_{n}", intri, (4, 5, 8, 12, 14), required=False)
        rot = _fs_sized(fe, f"Rot_{n}", extri, (9,), required=False)
        if rot is None:
            rot, _ = cv2.Rodrigues(_fs_sized(fe, f"R_{n}", extri, (3,)).reshape(3, 1))
        T = np.eye(4)
        T[:3, :3] = rot.reshape(3, 3)
        T[:3, 3] = _fs_sized(fe, f"T_{n}", extri, (3,)).reshape(3) * scale
        h = _fs_sized(fi, f"H_{n}", intri, (1,), required=False)
        w = _fs_sized(fi, f"W_{n}", intri, (1,), required=False)
        size = (
            (int(w.ravel()[0]), int(h.ravel()[0]))
            if h is not None and w is not None
            else (int(round(2 * K[0, 2])), int(round(2 * K[1, 2])))
        )
        d = tuple(np.zeros(5)) if dist is None else tuple(float(v) for v in dist.ravel())
        try:
            cams.append(Camera(K=K, cam_from_world=T, image_size=size, name=n, dist=d))
        except RigError as exc:
            raise CalibrationError(f"{intri}/{extri.name}: {exc}") from exc
    return cams


def read_easymocap(
    intri: str | Path, extri: str | Path, *, units: str | None = None
) -> tuple[CameraRig, str]:
    """Read EasyMocap / OpenCV ``intri.yml`` + ``extri.yml``; returns the rig in metres and the unit.

    Raises:
        CalibrationError: A file that OpenCV cannot open, or a missing field (named with its file).
    """
    intri, extri = Path(intri), Path(extri)
    units = units or "m"
    if units not in CALIBRATION_UNITS:
        raise CalibrationError(
            f"calibration units must be one of {', '.join(CALIBRATION_UNITS)}, got {units!r}"
        )
    for p in (intri, extri):
        if not p.is_file():
            raise CalibrationError(f"{p}: calibration file not found")
    import cv2

    fi, fe = _fs_open(intri), _fs_open(extri)
    if not fi.isOpened() or not fe.isOpened():
        raise CalibrationError(f"{intri if not fi.isOpened() else extri}: OpenCV cannot read this YAML file")
    try:
        cams = _easymocap_cameras(fi, fe, intri, extri, CALIBRATION_UNITS[units])
    except cv2.error as exc:  # a node of the wrong kind: OpenCV's multi-line message in one line
        raise CalibrationError(
            f"{intri} / {extri.name}: OpenCV cannot read a field: {_cv_message(exc)}"
        ) from exc
    fi.release()
    fe.release()
    return CameraRig(tuple(cams)), units


def _fixed_unit_reader(path: Path) -> Callable[[Path], tuple[CameraRig, str]] | None:
    """The reader of a format whose unit the format fixes (``gttdata.calibration_formats``), or None."""
    from gttdata import calibration_formats as cf

    name = path.name.lower()
    if name.endswith((".qca.txt", ".qca")):
        return cf.read_qca
    if name.endswith(".xcp"):
        return cf.read_xcp
    if name.endswith((".pickle", ".pkl")):
        return cf.read_opencap
    if name.endswith(".mcal"):
        return cf.refuse_unreadable  # type: ignore[return-value]
    if name.endswith(".toml") and path.is_file():
        try:
            d = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError):
            return None  # read_toml_calibration names the parse error
        if cf.is_caliscope(d):
            return cf.read_caliscope
    return None


def load_calibration(
    path: str | Path, *, units: str | None = None, warn: bool = True
) -> tuple[CameraRig, str]:
    """Read a calibration by its name.

    ``path`` is a ``.toml`` file (aniposelib / Pose2Sim / FreeMoCap, or Caliscope's camera array), a
    Qualisys ``.qca.txt``, a Vicon ``.xcp``, an ``intri.yml`` (its ``extri.yml`` next to it) or a folder
    holding ``intri.yml`` and ``extri.yml`` (layouts: :mod:`gttdata.calibration_formats`). Logs :func:`check_rig`'s warning when ``warn``.

    Returns:
        ``(rig, units)``: cameras in metres and the unit the file was read in.
    """
    path = Path(path)
    if not path.exists():
        raise CalibrationError(f"{path}: calibration file not found")
    fixed = _fixed_unit_reader(path)
    if fixed is not None:
        rig, used = fixed(path)
        if units is not None and units != used:
            raise CalibrationError(f"{path}: the format states its unit, {used!r}, but {units!r} was given")
    elif path.is_dir() or path.name.startswith(("intri", "extri")):
        folder = path if path.is_dir() else path.parent
        rig, used = read_easymocap(folder / "intri.yml", folder / "extri.yml", units=units)
    elif path.suffix.lower() == ".toml":
        rig, used = read_toml_calibration(path, units=units)
    else:
        raise CalibrationError(
            f"{path}: unknown calibration layout; expected .toml (aniposelib/Pose2Sim/FreeMoCap/Caliscope), "
            ".qca.txt (Qualisys), .xcp (Vicon) or intri.yml/extri.yml (EasyMocap)"
        )
    check_distortion(rig, path)
    if warn:
        msg = check_rig(rig, units=used, source=str(path))
        if msg:
            log.warning(msg)
    return rig, used


def save_calibration(rig: CameraRig, path: str | Path, *, units: str = "m") -> Path:
    """Write an aniposelib / Pose2Sim calibration TOML.

    Write ``rig`` (metres) as an aniposelib / Pose2Sim TOML with translations in ``units``
    (``metadata.units`` states it).
    """
    if units not in CALIBRATION_UNITS:
        raise ValueError(f"units must be one of {', '.join(CALIBRATION_UNITS)}, got {units!r}")
    import tomli_w

    d = _scaled(rig, 1.0 / CALIBRATION_UNITS[units]).to_dict()
    d["metadata"]["units"] = units
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(tomli_w.dumps(d))
    tmp.replace(path)
    return path


def undistort_points(pixels: np.ndarray, camera: Camera) -> np.ndarray:
    """Detected pixels mapped to the distortion-free image of the same intrinsics.

    Uses OpenCV's iterative ``undistortPoints`` run to convergence (OpenCV's distortion model: k1, k2, p1, p2[, k3,
    ...]) with ``P = K``; NaN pixels stay NaN. Without distortion coefficients the input is returned.

    Args:
        pixels: Pixels, shape ``(..., 2)``.
        camera: The camera (``K``, ``dist``).

    Returns:
        Undistorted pixels, shape ``(..., 2)``.
    """

    def undistort(xy: np.ndarray) -> np.ndarray:
        import cv2

        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
        dist = np.asarray(camera.dist, dtype=np.float64)
        und = cv2.undistortPoints(xy.reshape(-1, 1, 2), camera.K, dist, None, None, camera.K, crit)
        return np.asarray(und).reshape(-1, 2)

    return _map_finite_pixels(pixels, camera, undistort)


def _map_finite_pixels(
    pixels: np.ndarray, camera: Camera, fn: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """``fn`` applied to the finite pixels, shape ``(M, 2)`` in and out; NaN rows stay NaN; a copy without distortion.

    Args:
        pixels: Pixels, shape ``(..., 2)``.
        camera: The camera; with all-zero ``dist`` the pixels are returned unchanged (as a float64 copy).
        fn: The pixel map on finite rows.

    Returns:
        Mapped pixels, shape ``(..., 2)`` float64.
    """
    px = np.asarray(pixels, dtype=np.float64)
    if not np.any(np.asarray(camera.dist)):
        return px.copy()
    flat = px.reshape(-1, 2)
    ok = np.all(np.isfinite(flat), axis=1)
    out = np.full_like(flat, np.nan)
    if ok.any():
        out[ok] = fn(flat[ok])
    return out.reshape(px.shape)


def distort_points(pixels: np.ndarray, camera: Camera) -> np.ndarray:
    """Pinhole pixels mapped through the camera's lens distortion (inverse of :func:`undistort_points`).

    Uses OpenCV's ``projectPoints`` on the normalised coordinates ``K^-1 [u, v, 1]``; NaN stays NaN.

    Args:
        pixels: Distortion-free pixels, shape ``(..., 2)``.
        camera: The camera (``K``, ``dist``).

    Returns:
        Distorted pixels, shape ``(..., 2)``.
    """

    def distort(xy: np.ndarray) -> np.ndarray:
        import cv2

        xn = np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1) @ np.linalg.inv(camera.K).T
        xn /= xn[:, 2:3]
        proj, _ = cv2.projectPoints(
            xn.reshape(-1, 1, 3),
            np.zeros(3),
            np.zeros(3),
            camera.K,
            np.asarray(camera.dist, dtype=np.float64),
        )
        return np.asarray(proj).reshape(-1, 2)

    return _map_finite_pixels(pixels, camera, distort)
