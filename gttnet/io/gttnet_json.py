"""The GTT-Net JSON layout (per-image rays and centres, images in true time order): reader and writer.

Two variants are read. Ours carries intrinsics ``K`` (3 x 3V). The authors' released test files carry
the scalar ``K = 0`` and give the viewing rays directly, plus a time ``t`` per image, ``limbSeq``
(the skeleton's limbs), ``X_init`` (their initial structure) and ``rayDInd`` (their neighbour
ranking per image). :func:`write_gttnet_json` writes a capture in the authors' variant.
"""

from __future__ import annotations

import json
import logging
import os
import warnings
from pathlib import Path

import numpy as np

from gttdata.skeleton import Skeleton, default_skeleton
from gttnet.errors import ImportFormatError
from gttnet.geometry.ordering import stream_ranks
from gttnet.io._views import UNITS, ImportedCapture, resolve_units

__all__ = [
    "RAY_FOCAL_PX",
    "adjacency_lists",
    "read_gttnet_json",
    "rays_to_pixels",
    "skeleton_from_limbs",
    "write_gttnet_json",
]

#: Focal length (pixels) of the synthetic intrinsics given to files that store rays without ``K``.
RAY_FOCAL_PX = 1000.0

log = logging.getLogger(__name__)


def _array(path: Path, d: dict, key: str, ndim: int) -> np.ndarray:
    if key not in d:
        raise ImportFormatError(f"{path}: field '{key}': expected a numeric array, found no such key")
    try:
        a = np.asarray(d[key], dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ImportFormatError(
            f"{path}: field '{key}': expected a rectangular numeric array, found {exc}"
        ) from exc
    if a.ndim != ndim:
        raise ImportFormatError(f"{path}: field '{key}': expected a {ndim}-D array, found shape {a.shape}")
    return a


def _ndim(value: object) -> int:
    """Dimensions of a JSON value read as an array; -1 for a ragged one."""
    try:
        return int(np.ndim(value))  # type: ignore[arg-type]
    except ValueError:
        return -1


def _vector(path: Path, d: dict, key: str) -> np.ndarray:
    """A numeric vector stored flat, as a row (1 x N) or as a column (N x 1)."""
    a = _array(path, d, key, _ndim(d.get(key, [])) if _ndim(d.get(key, [])) in (1, 2) else 1)
    if a.ndim == 2 and 1 not in a.shape:
        raise ImportFormatError(
            f"{path}: field '{key}': expected a vector of N values, found shape {a.shape}"
        )
    a = a.ravel()
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise ImportFormatError(
            f"{path}: field '{key}': expected N finite values, found {a.size} with NaN/inf or none"
        )
    return a


def _look_along(z: np.ndarray) -> np.ndarray:
    """A world→camera rotation whose optical axis (camera +z) is the unit vector ``z``."""
    up = np.eye(3)[int(np.argmin(np.abs(z)))]  # the world axis least aligned with z
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def rays_to_pixels(
    rays: np.ndarray, visible: np.ndarray, cam_id: np.ndarray, K: np.ndarray, *, per_image: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels and a world→camera rotation that reproduce given world rays exactly through ``K``.

    The layout stores rays but no rotations. Any rotation R turns a ray r into the pixel
    ``K R r`` (dehomogenised), and ``Observations.rays()`` maps it back to ``R^T K^-1 [u v 1]`` = r; so
    each camera (or, with ``per_image``, each image) gets the rotation whose optical axis is the mean of
    its observed rays, which keeps all of them in front of the camera. Per-image rotations suit cameras
    that pan and tilt (a pose per image, as in broadcast footage), whose rays over a whole capture can
    span more than a hemisphere.

    Args:
        rays: Unit world rays, shape ``(N, J, 3)``.
        visible: Observed mask, shape ``(N, J)``.
        cam_id: Camera of each image in ``[0, V)``, shape ``(N,)``.
        K: Intrinsics per camera, shape ``(V, 3, 3)``.
        per_image: One rotation per image instead of one per camera.

    Returns:
        ``(pixels (N, J, 2) NaN where missing, R (N, 3, 3) world→camera of each image)``.

    Raises:
        ValueError: If a camera (or an image) sees rays spread over more than a hemisphere.
    """
    group = np.arange(cam_id.shape[0]) if per_image else cam_id
    n_groups = int(group.max()) + 1 if group.size else 0
    masked = np.where(visible[..., None], rays, 0.0).sum(axis=1)  # (N, 3) sum of each image's rays
    sums = np.zeros((n_groups, 3))
    np.add.at(sums, group, masked)
    Rg = np.empty((n_groups, 3, 3))
    for g in range(n_groups):
        m = sums[g]
        Rg[g] = _look_along(m / np.linalg.norm(m)) if np.linalg.norm(m) > 0 else np.eye(3)
    R = Rg[group]
    cam_rays = np.einsum("nab,njb->nja", R, rays)
    if np.any(cam_rays[..., 2][visible] <= 1e-6):
        what = "one image" if per_image else "one camera"
        raise ValueError(f"rays of {what} span more than a hemisphere; cannot express them as pixels")
    h = np.einsum("nab,njb->nja", K[cam_id], cam_rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        px = h[..., :2] / h[..., 2:3]
    px[~visible] = np.nan
    return px, R


def skeleton_from_limbs(limbs: np.ndarray, n_joints: int) -> Skeleton:
    """A skeleton for ``n_joints`` joints from an undirected limb list.

    A registered topology (:mod:`gttdata.skeletons`) with the same joint count and the same limb set
    is returned as is (so a COCO-17 or H36M-17 file gets its joint names). Otherwise the tree is a
    breadth-first spanning forest from joint 0 (then from the lowest unreached joint), limbs that
    would close a cycle become ``extra_bones``, and joints are named ``j0``, ``j1``...

    Args:
        limbs: 0-based joint index pairs, shape ``(L, 2)``.
        n_joints: Number of joints J.
    """
    from gttdata.skeletons import available_skeletons, get_skeleton

    want = {frozenset((int(a), int(b))) for a, b in limbs if a != b}
    for name in available_skeletons():
        sk = get_skeleton(name)
        if sk.n_joints == n_joints and {frozenset(map(int, e)) for e in sk.limbs} == want:
            return sk
    from gttdata.skeletons_detectors import skeleton_from_edges

    names = tuple(f"j{i}" for i in range(n_joints))
    return skeleton_from_edges(f"limbs{n_joints}", names, [(names[a], names[b]) for a, b in map(tuple, want)])


def _unwrap(raw: object) -> object:
    """Strip the extra list levels MATLAB's JSON export adds around a cell array of rows.

    ``[[[0, 1, 2], [1, 3]]]`` (the whole list wrapped once more) and ``[[[0, 1, 2]], [[1, 3]]]`` (each row
    wrapped) both become ``[[0, 1, 2], [1, 3]]``.
    """
    while (
        isinstance(raw, list)
        and len(raw) == 1
        and isinstance(raw[0], list)
        and raw[0]
        and all(isinstance(r, list) for r in raw[0])
    ):
        raw = raw[0]
    if (
        isinstance(raw, list)
        and raw
        and all(isinstance(r, list) and len(r) == 1 and isinstance(r[0], list) for r in raw)
    ):
        raw = [r[0] for r in raw]
    return raw


def _limb_rows(path: Path, raw: object) -> tuple[list[list[float]], str]:
    """``limbSeq`` as rows of numbers and the form they take: ``"pairs"`` or ``"adjacency"``.

    Pairs: a rectangular (L, 2) or (2, L) table. Adjacency lists: rows ``[joint, neighbour, ...]`` of any
    length (a bare number is a joint without neighbours, as MATLAB writes a 1-element row); a rectangular
    table whose rows are neither 2 long nor 2 in number is read as adjacency lists too.
    """
    raw = _unwrap(raw)
    if not isinstance(raw, list) or not raw:
        raise ImportFormatError(
            f"{path}: field 'limbSeq': expected joint index pairs or adjacency lists, found {raw!r:.60}"
        )
    rows: list[list[float]] = []
    for i, r in enumerate(raw):
        row = r if isinstance(r, list) else [r]
        if not row or not all(isinstance(x, int | float) and not isinstance(x, bool) for x in row):
            raise ImportFormatError(
                f"{path}: field 'limbSeq': row {i}: expected a list of joint indices, found {r!r:.60}"
            )
        rows.append([float(x) for x in row])
    lengths = {len(r) for r in rows}
    if lengths == {2}:
        return rows, "pairs"
    if len(rows) == 2 and len(lengths) == 1 and min(lengths) > 2:
        return [list(c) for c in zip(*rows, strict=True)], "pairs"  # (2, L): one limb per column
    return rows, "adjacency"


def _limbs(path: Path, d: dict, p: int) -> np.ndarray | None:
    """``limbSeq`` as 0-based pairs ``(L, 2)``, or None when absent.

    Read in either published form (:func:`_limb_rows`): index pairs (L x 2 or 2 x L), or the authors'
    adjacency lists ``[joint, neighbour, neighbour, ...]``, possibly wrapped in one more list. Indices are
    0-based or 1-based (MATLAB and OpenPose style): 1-based when no index is 0 and the largest is P.
    """
    if "limbSeq" not in d:
        return None
    rows, form = _limb_rows(path, d["limbSeq"])
    if form == "pairs":
        pairs = rows
    else:
        pairs = [[row[0], x] for row in rows for x in row[1:]]
    if not pairs:
        raise ImportFormatError(
            f"{path}: field 'limbSeq': expected at least one limb, found {len(rows)} adjacency rows "
            "without neighbours"
        )
    a = np.asarray(pairs, dtype=np.float64)
    if not np.all(np.isfinite(a)) or np.any(a != np.round(a)):
        bad = a[~np.isfinite(a) | (a != np.round(a))][0]
        raise ImportFormatError(f"{path}: field 'limbSeq': expected integer joint indices, found {bad}")
    a = a.astype(np.int64)
    if a.min() >= 1 and a.max() == p:
        a = a - 1
    if a.min() < 0 or a.max() >= p:
        raise ImportFormatError(
            f"{path}: field 'limbSeq': expected joint indices in [0, {p}) or [1, {p}] for P = {p} joints, "
            f"found {a.min()}..{a.max()}"
        )
    return a


def _camera_ids(path: Path, d: dict, n: int, C: np.ndarray) -> np.ndarray:
    """``camID`` per image: N ids, or V ids cycling over the N images (V dividing N).

    Without ``camID``, images that share a centre ``C`` (3, N) are one camera, and a warning says so.
    """
    if "camID" not in d:
        _, cam_raw = np.unique(np.round(C.T, 9), axis=0, return_inverse=True)
        warnings.warn(
            f"{path}: no 'camID' field; images that share a camera centre are taken as one camera "
            f"({int(cam_raw.max()) + 1} cameras)",
            UserWarning,
            stacklevel=3,
        )
        return cam_raw.ravel().astype(np.float64)
    cam_raw = _vector(path, d, "camID")
    if cam_raw.shape[0] != n:
        if cam_raw.shape[0] > n or n % cam_raw.shape[0]:
            raise ImportFormatError(
                f"{path}: field 'camID': expected N = {n} camera ids (one per image) or V ids cycling over "
                f"the images (V dividing N), found {cam_raw.shape[0]}"
            )
        cam_raw = np.resize(cam_raw, n)
    return cam_raw


def _intrinsics(path: Path, d: dict, V: int) -> tuple[np.ndarray, bool]:
    """Per-camera ``K`` (V, 3, 3) and whether the file gives rays only (``K`` = 0 or absent: synthetic K)."""
    if "K" not in d or (_ndim(d["K"]) >= 0 and np.size(d["K"]) == 1):
        k0 = np.asarray(d.get("K", 0), dtype=object).ravel()[0]
        if not isinstance(k0, int | float) or k0 != 0:
            raise ImportFormatError(
                f"{path}: field 'K': expected a (3, 3V) array or the scalar 0 (rays only), found {d['K']!r}"
            )
        f = RAY_FOCAL_PX
        return np.tile(np.array([[f, 0.0, 0.0], [0.0, f, 0.0], [0.0, 0.0, 1.0]]), (V, 1, 1)), True
    Kall = _array(path, d, "K", 2)
    if Kall.shape != (3, 3 * V):
        raise ImportFormatError(
            f"{path}: field 'K': expected shape (3, 3V) = {(3, 3 * V)} for {V} cameras, found {Kall.shape}"
        )
    K = Kall.reshape(3, V, 3).transpose(1, 0, 2)
    if np.any(np.abs(np.linalg.det(K)) < 1e-12):
        raise ImportFormatError(
            f"{path}: field 'K': expected non-singular 3 x 3 blocks, found a singular one"
        )
    return K, False


def _time_rank(path: Path, d: dict, n: int) -> np.ndarray:
    """Rank of each image in true time: from ``t`` when present, else the file order."""
    if "t" not in d:
        return np.arange(n, dtype=np.int64)
    t = _vector(path, d, "t")
    if t.shape[0] != n:
        raise ImportFormatError(f"{path}: field 't': expected N = {n} capture times, found {t.shape[0]}")
    rank = np.empty(n, dtype=np.int64)
    rank[np.argsort(t, kind="stable")] = np.arange(n)
    return rank


def _units(path: Path, d: dict, given: str | None) -> str:
    """The file's ``units`` key, else ``given``, else metres with a warning."""
    try:
        return resolve_units(path, "gttnet-json", given, d.get("units"))
    except ValueError as exc:
        raise ImportFormatError(str(exc)) from exc


def _pixels(
    path: Path,
    rays: np.ndarray,
    visible: np.ndarray,
    cam: np.ndarray,
    C: np.ndarray,
    K: np.ndarray,
    rays_only: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels ``(N, P, 2)``, rotations ``(N, 3, 3)`` and image sizes ``(V, 2)`` for the stored rays.

    ``K`` (V, 3, 3) is updated in place: with synthetic intrinsics (``rays_only``) each camera's principal
    point is moved to the centre of an image sized to hold all of its pixels. ``C`` is (3, N).
    """
    V = K.shape[0]
    # A camera whose centre moves between its images pans and tilts too (a pose per image): give each
    # image its own rotation. So does a fixed camera whose rays span more than one hemisphere.
    tol = 1e-9 * max(1.0, float(np.abs(C).max()))
    moving = any(float(np.ptp(C[:, cam == c], axis=1).max()) > tol for c in range(V) if np.any(cam == c))
    try:
        px, R = rays_to_pixels(rays, visible, cam, K, per_image=moving)
    except ValueError:
        try:
            px, R = rays_to_pixels(rays, visible, cam, K, per_image=True)
        except ValueError as exc:
            raise ImportFormatError(f"{path}: field 'ray': {exc}") from exc
    if not rays_only:
        return px, R, np.round(2.0 * K[:, :2, 2]).astype(np.int32)
    # Centre each synthetic image on its camera's pixels, and size it to hold them all.
    size = np.empty((V, 2), dtype=np.int32)
    for c in range(V):
        sel = visible & (cam == c)[:, None]
        half = np.abs(px[sel]).max(axis=0) if sel.any() else np.full(2, 1.0)
        size[c] = 2 * np.ceil(half + 10.0)
        K[c, :2, 2] = size[c] / 2.0
    return px + K[cam][:, None, :2, 2], R, size


def read_gttnet_json(path: str | Path, *, units: str | None = None) -> ImportedCapture:
    """Read a GTT-Net JSON file (ours or the authors' variant).

    Layout: ``ray`` (3P x N unit world rays, joint-major rows; an all-zero ray is a missing joint)
    fixes N images and P joints. ``C`` (3 x N camera centres). ``camID``: the camera of each image,
    any integers (cameras are numbered by sorted id); a list of V < N ids whose length divides N
    means the images cycle over the cameras (image n has ``camID[n % V]``). ``K``: 3 x 3V
    intrinsics (camera c in columns 3c..3c+2), or the scalar 0 when the file gives rays only (then
    each camera gets synthetic intrinsics with focal :data:`RAY_FOCAL_PX`). Optional: ``point3D``
    (3P x N ground truth), ``t`` (N capture times; the true order, otherwise the file order),
    ``limbSeq`` (the skeleton: the authors' adjacency lists ``[joint, neighbour, ...]``, possibly wrapped
    in one more list, or L limbs as index pairs; see :func:`_limbs` and :func:`skeleton_from_limbs`).
    ``camID`` may be absent: images sharing a centre are then one camera (with a warning), and ``K`` may
    be absent (rays only). A camera whose centre moves from image to image (pan-tilt-zoom) gets a
    rotation per image.
    ``X_init``, ``rayDInd`` and ``A_GT`` are accepted and ignored: every method computes its own
    initial structure and neighbours from the rays. ``units`` (ours, optional): the length unit of
    ``C`` and ``point3D``; the authors' files record none (theirs are in inches). Rays become pixels through ``K`` and a synthetic
    rotation per camera (:func:`rays_to_pixels`), so ``Observations.rays()`` returns the stored rays.

    Args:
        path: The ``.json`` file.
        units: Length unit of ``C`` and ``point3D`` (key of :data:`gttnet.io._views.UNITS`); None: the
            file's ``units`` key, else metres with a warning (:func:`~gttnet.io._views.resolve_units`).

    Returns:
        The capture in time order, with its time rank and (when stored) ground truth.

    Raises:
        ImportFormatError: Naming the file, the field, what was expected and what was found.
    """
    path = Path(path)
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ImportFormatError(
            f"{path}: line {exc.lineno}: expected JSON, found invalid text ({exc.msg})"
        ) from exc
    except UnicodeDecodeError as exc:
        raise ImportFormatError(f"{path}: expected UTF-8 JSON text, found binary data") from exc
    if not isinstance(d, dict):
        raise ImportFormatError(f"{path}: expected a JSON object, found {type(d).__name__}")
    units = _units(path, d, units)
    scale = UNITS[units]
    ray = _array(path, d, "ray", 2)
    if ray.shape[0] % 3 or ray.shape[0] == 0 or ray.shape[1] == 0:
        raise ImportFormatError(
            f"{path}: field 'ray': expected shape (3P, N) with P, N > 0, found {ray.shape}"
        )
    p, n = ray.shape[0] // 3, ray.shape[1]
    X = None
    if "point3D" in d:
        X = _array(path, d, "point3D", 2)
        if X.shape != (3 * p, n):
            raise ImportFormatError(
                f"{path}: field 'point3D': expected shape (3P, N) = {(3 * p, n)}, found {X.shape}"
            )
    C = _array(path, d, "C", 2)
    if C.shape != (3, n):
        raise ImportFormatError(f"{path}: field 'C': expected shape (3, N) = {(3, n)}, found {C.shape}")
    cam_raw = _camera_ids(path, d, n, C)
    ids, cam = np.unique(cam_raw, return_inverse=True)
    cam = cam.ravel()
    V = ids.shape[0]
    rays = ray.reshape(p, 3, n).transpose(2, 0, 1)  # joint-major rows -> (N, P, 3)
    norm = np.linalg.norm(rays, axis=-1)
    visible = norm > 0
    if not np.all(np.isfinite(rays)):
        raise ImportFormatError(f"{path}: field 'ray': expected finite values, found NaN or inf")
    if np.any(np.abs(norm[visible] - 1.0) > 1e-3):
        bad = float(norm[visible][np.argmax(np.abs(norm[visible] - 1.0))])
        raise ImportFormatError(
            f"{path}: field 'ray': expected unit rays or all-zero (missing), found norm {bad:.4g}"
        )
    K, rays_only = _intrinsics(path, d, V)
    px, R, size = _pixels(path, rays, visible, cam, C, K, rays_only)
    rank = _time_rank(path, d, n)
    limbs = _limbs(path, d, p)
    skeleton = default_skeleton(p, "imported") if limbs is None else skeleton_from_limbs(limbs, p)
    centres = C.T * scale
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = -np.einsum("nab,nb->na", R, centres)
    stream = stream_ranks(rank, cam).astype(np.int32)
    log.info(
        "%s: %d images, %d joints (%s), %d cameras (units %s%s)",
        path, n, p, skeleton.name, V, units, ", rays only" if rays_only else "",
    )  # fmt: skip
    return ImportedCapture(
        source=str(path),
        skeleton=skeleton,
        cam_id=cam.astype(np.int32),
        stream_index=stream,
        K=K[cam],
        cam_from_world=T,
        keypoints_px=px,
        visible=visible,
        image_size=size,
        time_rank=rank,
        points3d=None if X is None else X.reshape(p, 3, n).transpose(2, 0, 1) * scale,
        file_units=units,
    )


def adjacency_lists(limbs: np.ndarray) -> list[list[int]]:
    """Limb pairs as adjacency rows ``[joint, neighbour, neighbour, ...]``, each limb once.

    Each limb is listed under its first joint; rows follow the joints' order.

    Args:
        limbs: Joint index pairs, shape ``(L, 2)`` (any base: indices are written as given).

    Returns:
        One row per joint that starts a limb.

    Example:
        >>> adjacency_lists(np.array([[1, 2], [1, 3], [3, 4]]))
        [[1, 2, 3], [3, 4]]
    """
    rows: dict[int, list[int]] = {}
    for a, b in np.asarray(limbs, dtype=np.int64).tolist():
        rows.setdefault(a, [a]).append(b)
    return [rows[k] for k in sorted(rows)]


def write_gttnet_json(
    sample,
    path: str | Path,
    *,
    units: str = "m",
    n_ranked: int = 20,
    overwrite: bool = False,
    limb_format: str = "adjacency",
) -> Path:
    """Write a capture in the authors' GTT-Net JSON layout (rays only, ``K`` = 0).

    Images are written in true time order with ``camID`` (1-based), ``t`` (seconds), ``C``, ``ray``,
    ``point3D`` (the ground truth), ``limbSeq`` (1-based adjacency lists, or limb pairs), ``X_init`` and ``rayDInd``
    (pseudo-triangulation's initial structure and its ``n_ranked`` best neighbours per image, 1-based),
    and ``units``, the length unit (a key the authors' files lack and their code ignores).
    :func:`read_gttnet_json` reads it back to the same rays, centres, order and ground truth.

    Args:
        sample: A :class:`gttdata.capture.sample.CaptureSample` (true time order, ground truth).
        path: Output ``.json``; written to a temporary name, then renamed.
        units: Length unit of ``C``, ``point3D`` and ``X_init`` (key of ``UNITS``), recorded in the file.
        n_ranked: Neighbours per image in ``rayDInd``.
        overwrite: Replace an existing file.
        limb_format: ``"adjacency"`` (the authors' published form: rows ``[joint, neighbour, ...]``,
            1-based) or ``"pairs"`` (one 1-based ``[joint, joint]`` row per limb).

    Returns:
        The path written.

    Raises:
        FileExistsError: ``path`` exists and ``overwrite`` is False.
    """
    from gttdata.capture.views import make_view
    from gttnet.geometry.triangulation import pseudo_triangulate

    path = Path(path)
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path}: exists; pass overwrite=True (--overwrite) to replace it")
    scale = UNITS[units]
    obs, gt = make_view(sample, "full")
    n, p = obs.keypoints_px.shape[:2]
    rays, centres = obs.rays(), obs.centers()
    pt = pseudo_triangulate(centres, rays, obs.visible, obs.cam_id)

    def joint_major(a: np.ndarray) -> list:
        return a.transpose(1, 2, 0).reshape(3 * p, n).tolist()  # (N, P, 3) -> (3P, N)

    if limb_format not in ("adjacency", "pairs"):
        raise ValueError(f"limb_format: expected 'adjacency' or 'pairs', found {limb_format!r}")
    limbs = obs.skeleton.limbs + 1
    limb_seq = limbs.tolist() if limb_format == "pairs" else adjacency_lists(limbs)
    d = {
        "camID": (obs.cam_id.astype(np.int64) + 1).tolist(),
        "t": gt.timestamp_s.tolist(),
        "K": 0,
        "C": (centres.T / scale).tolist(),
        "ray": joint_major(rays),
        "point3D": joint_major(gt.points3d / scale),
        "limbSeq": limb_seq,
        "X_init": joint_major(pt.X_init / scale),
        "rayDInd": (pt.order[:, : min(n_ranked, n)] + 1).tolist(),
        "units": units,
    }
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(d))
    os.replace(tmp, path)
    return path
