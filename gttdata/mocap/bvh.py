"""Biovision BVH loader: parse the hierarchy and frames, then run forward kinematics to joint positions.

Conventions:
    * Each joint's rotation order is the order of its rotation channels on the ``CHANNELS`` line,
      applied intrinsically: ``Zrotation Yrotation Xrotation`` gives ``R = Rz @ Ry @ Rx``. A joint
      may have 0 to 3 rotation channels and position channels anywhere on the line.
    * Position channels, when present, replace the matching ``OFFSET`` component (the common reading
      of root channels; CMU roots have a zero offset so both readings agree).
    * ``End Site`` blocks are not joints: a joint sits where its ``OFFSET`` puts it, as in the file.
      For the CMU conversions this puts e.g. ``LHipJoint`` on ``Hips`` (zero offset), i.e. each
      joint at the start of its ASF bone, as :func:`gttdata.mocap.asfamc.load_amc` does by default.
    * Axes: BVH is y-up. World is z-up, so ``(x, y, z)_bvh -> (x, -z, y)_world`` (a +90 degree
      rotation about x; right-handed, forward ``+z_bvh`` becomes ``-y_world``). Pass
      ``up_axis="z"`` for files that are already z-up.
    * Units: ``scale`` metres per file unit. By default the CMU conversions (joint names matching
      ``CMU31_BVH_ALIASES``) use 0.0254 / 0.45 (CMU's 1/0.45 inch). Any other file gets the unit
      among metres, centimetres and millimetres (a factor 10 apart) that makes the figure's height,
      the 95th percentile over frames of the joints' vertical extent, closest to 1.5 m in log scale
      (:func:`guess_scale_m`; Boxing_Toes: 153 units, so centimetres). A height outside
      0.8-2.5 m after scaling warns: inches, feet or non-human figures need an explicit ``scale``.
"""

from __future__ import annotations

import logging
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gttdata.errors import MotionFormatError
from gttdata.mocap import register_loader
from gttdata.mocap.motion import Motion
from gttdata.skeleton import CMU31_BVH_ALIASES, Skeleton, cmu31

__all__ = ["CMU_BVH_SCALE_M", "BvhData", "forward_kinematics", "guess_scale_m", "load_bvh", "parse_bvh"]

_log = logging.getLogger(__name__)

#: Metres per CMU length unit: the CMU ASF files declare ``length 0.45``, so one unit is 1/0.45 inch.
CMU_BVH_SCALE_M: float = 0.0254 / 0.45
#: Candidate units of non-CMU files for the automatic scale, metres per unit.
_AUTO_UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Joints' vertical extent of a standing adult (stature less the head top and the soles), metres.
_TYPICAL_EXTENT_M = 1.5
_PLAUSIBLE_EXTENT_M = (0.8, 2.5)
_CHANNELS = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


@dataclass
class _Joint:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str] = field(default_factory=list)
    first_column: int = 0
    end_sites: list[np.ndarray] = field(default_factory=list)


@dataclass
class BvhData:
    """Raw content of a BVH file, in file units and axes.

    Args:
        names: Joint names in file order (End Sites excluded), length J.
        parents: Parent index per joint (-1 for roots), length J.
        offsets: Joint offsets from the parent, file units, shape ``(J, 3)``.
        channels: Channel names per joint.
        columns: First motion column of each joint, length J.
        values: Motion rows, shape ``(T, C)``; degrees for rotations, file units for positions.
        frame_time_s: Seconds per frame from the header.
        end_sites: ``(parent joint index, OFFSET)`` of every End Site, file units.
    """

    names: list[str]
    parents: list[int]
    offsets: np.ndarray
    channels: list[list[str]]
    columns: list[int]
    values: np.ndarray
    frame_time_s: float
    end_sites: list[tuple[int, np.ndarray]] = field(default_factory=list)


class _Tokens:
    """Whitespace tokens of the hierarchy with their line numbers, for one-line errors."""

    def __init__(self, path: Path, lines: list[str]) -> None:
        self.path = path
        self.items = [(tok, i + 1) for i, line in enumerate(lines) for tok in line.split()]
        self.pos = 0
        self.last_line = len(lines)

    def peek(self) -> str | None:
        return self.items[self.pos][0] if self.pos < len(self.items) else None

    def line(self) -> int:
        return self.items[self.pos][1] if self.pos < len(self.items) else self.last_line

    def next(self, expected: str) -> str:
        if self.pos >= len(self.items):
            raise MotionFormatError(
                f"{self.path}: line {self.last_line}: expected {expected}, found end of file"
            )
        tok = self.items[self.pos][0]
        self.pos += 1
        return tok

    def expect(self, word: str) -> None:
        line = self.line()
        tok = self.next(repr(word))
        if tok != word:
            raise MotionFormatError(f"{self.path}: line {line}: expected {word!r}, found {tok!r}")

    def number(self, what: str) -> float:
        line = self.line()
        tok = self.next(what)
        try:
            v = float(tok)
        except ValueError:
            raise MotionFormatError(
                f"{self.path}: line {line}: {what} must be a number, found {tok!r}"
            ) from None
        if not math.isfinite(v):
            raise MotionFormatError(f"{self.path}: line {line}: {what} must be finite, found {tok!r}")
        return v


def _parse_joint(tk: _Tokens, joints: list[_Joint], parent: int, n_columns: int) -> int:
    """Parse ``NAME { OFFSET .. CHANNELS .. children }`` after ROOT/JOINT; returns the column count."""
    line = tk.line()
    name = tk.next("a joint name")
    if name == "{":
        raise MotionFormatError(f"{tk.path}: line {line}: expected a joint name, found '{{'")
    if any(j.name == name for j in joints):
        raise MotionFormatError(f"{tk.path}: line {line}: joint name {name!r} is used twice")
    tk.expect("{")
    tk.expect("OFFSET")
    offset = np.array([tk.number(f"OFFSET of {name}") for _ in range(3)])
    joint = _Joint(name, parent, offset, first_column=n_columns)
    index = len(joints)
    joints.append(joint)
    if tk.peek() == "CHANNELS":
        tk.next("CHANNELS")
        line = tk.line()
        count = tk.number(f"CHANNELS count of {name}")
        if count != int(count) or not 0 <= count <= 6:
            raise MotionFormatError(f"{tk.path}: line {line}: CHANNELS count must be 0..6, found {count:g}")
        for _ in range(int(count)):
            line = tk.line()
            ch = tk.next(f"a channel name of {name}")
            if ch not in _CHANNELS or ch in joint.channels:
                raise MotionFormatError(
                    f"{tk.path}: line {line}: channel of {name} must be a distinct one of "
                    f"{', '.join(_CHANNELS)}, found {ch!r}"
                )
            joint.channels.append(ch)
    n_columns += len(joint.channels)
    while True:
        line = tk.line()
        tok = tk.next("'JOINT', 'End' or '}'")
        if tok == "}":
            return n_columns
        if tok == "JOINT":
            n_columns = _parse_joint(tk, joints, index, n_columns)
        elif tok == "End":
            tk.expect("Site")
            tk.expect("{")
            tk.expect("OFFSET")
            joint.end_sites.append(np.array([tk.number(f"End Site OFFSET of {name}") for _ in range(3)]))
            tk.expect("}")
        else:
            raise MotionFormatError(f"{tk.path}: line {line}: expected 'JOINT', 'End' or '}}', found {tok!r}")


def _parse_header_value(path: Path, lines: list[str], i: int, key: str) -> str:
    if i >= len(lines):
        raise MotionFormatError(f"{path}: line {i}: expected '{key}', found end of file")
    text = lines[i].strip()
    if not text.startswith(key):
        raise MotionFormatError(f"{path}: line {i + 1}: expected '{key} <value>', found {text[:40]!r}")
    return text[len(key) :].strip()


def _parse_rows(
    path: Path, lines: list[str], first_line: int, n_columns: int, names: list[str]
) -> np.ndarray:
    """Motion rows as floats, shape ``(T, n_columns)``; errors name the line and column."""
    rows = []
    for k, line in enumerate(lines):
        parts = line.split()
        if not parts:
            continue
        if len(parts) != n_columns:
            raise MotionFormatError(
                f"{path}: line {first_line + k}: expected {n_columns} values, found {len(parts)} "
                "(truncated or malformed frame)"
            )
        rows.append((first_line + k, parts))
    if not rows:
        raise MotionFormatError(f"{path}: MOTION section has zero frames; expected at least 1")
    try:
        values = np.array([p for _, p in rows], dtype=np.float64)
    except ValueError:
        for lineno, parts in rows:
            for c, tok in enumerate(parts):
                try:
                    float(tok)
                except ValueError:
                    raise MotionFormatError(
                        f"{path}: line {lineno}: column {c + 1} must be a number, found {tok!r}"
                    ) from None
        raise
    bad = np.argwhere(~np.isfinite(values))
    if len(bad):
        r, c = bad[0]
        raise MotionFormatError(
            f"{path}: line {rows[r][0]}: column {c + 1} must be finite, found {rows[r][1][c]!r}"
        )
    return values


def parse_bvh(path: str | Path) -> BvhData:
    """Parse a BVH file without kinematics.

    Raises:
        MotionFormatError: One line naming the file, line, expected and found.
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="strict").splitlines()
    except UnicodeDecodeError as exc:
        raise MotionFormatError(
            f"{path}: expected a text BVH file, found undecodable bytes ({exc.reason})"
        ) from exc
    try:
        motion_at = next(i for i, s in enumerate(lines) if s.strip() == "MOTION")
    except StopIteration:
        raise MotionFormatError(f"{path}: expected a 'MOTION' line, found none (truncated file?)") from None
    tk = _Tokens(path, lines[:motion_at])
    tk.expect("HIERARCHY")
    joints: list[_Joint] = []
    n_columns = 0
    while tk.peek() is not None:
        tk.expect("ROOT")
        n_columns = _parse_joint(tk, joints, -1, n_columns)
    if not joints:
        raise MotionFormatError(
            f"{path}: line {motion_at + 1}: expected a ROOT joint before MOTION, found none"
        )
    frames_text = _parse_header_value(path, lines, motion_at + 1, "Frames:")
    time_text = _parse_header_value(path, lines, motion_at + 2, "Frame Time:")
    try:
        n_header = int(frames_text)
        frame_time = float(time_text)
    except ValueError:
        raise MotionFormatError(
            f"{path}: line {motion_at + 2}: expected an integer 'Frames:' and a number 'Frame Time:', "
            f"found {frames_text!r} and {time_text!r}"
        ) from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise MotionFormatError(f"{path}: line {motion_at + 3}: Frame Time must be > 0, found {time_text!r}")
    names = [j.name for j in joints]
    values = _parse_rows(path, lines[motion_at + 3 :], motion_at + 4, n_columns, names)
    if values.shape[0] != n_header:
        warnings.warn(
            f"{path}: header says {n_header} frames but the file holds {values.shape[0]} rows; using the rows",
            stacklevel=3,
        )
    return BvhData(
        names=names,
        parents=[j.parent for j in joints],
        offsets=np.stack([j.offset for j in joints]),
        channels=[j.channels for j in joints],
        columns=[j.first_column for j in joints],
        values=values,
        frame_time_s=frame_time,
        end_sites=[(i, off) for i, j in enumerate(joints) for off in j.end_sites],
    )


def rest_stature(data: BvhData, *, up: int) -> float:
    """Height of the rest (zero-rotation) pose from its lowest to its highest point, End Sites included.

    The joints alone stop at the base of the skull and the ankles/toe joints; the End Sites reach the top
    of the head and the toe tips, so this is the figure's stature in file units.

    Args:
        data: Parsed file.
        up: Index of the file's up axis (1 for y-up, 2 for z-up).
    """
    rest = np.zeros_like(data.offsets)
    for j, p in enumerate(data.parents):
        rest[j] = data.offsets[j] + (rest[p] if p >= 0 else 0.0)
    points = [rest] + [rest[p] + off for p, off in data.end_sites]
    return float(np.ptp(np.vstack(points)[:, up]))


def forward_kinematics(data: BvhData) -> np.ndarray:
    """Joint positions in file units and axes, vectorised over frames.

    Args:
        data: Parsed file.

    Returns:
        Positions, shape ``(T, J, 3)``, file units, file axes.
    """
    T, J = data.values.shape[0], len(data.names)
    pos = np.zeros((T, J, 3))
    rots: list[Rotation] = []
    for j in range(J):
        chans, col = data.channels[j], data.columns[j]
        trans = np.broadcast_to(data.offsets[j], (T, 3)).copy()
        rot_axes, rot_cols = "", []
        for k, ch in enumerate(chans):
            axis = "XYZ".index(ch[0])
            if ch.endswith("position"):
                trans[:, axis] = data.values[:, col + k]
            else:
                rot_axes += ch[0]
                rot_cols.append(col + k)
        # Upper-case axes: intrinsic rotations, so "ZYX" composes Rz @ Ry @ Rx as BVH prescribes.
        local = (
            Rotation.from_euler(rot_axes, data.values[:, rot_cols], degrees=True)
            if rot_axes
            else Rotation.identity(T)
        )
        p = data.parents[j]
        if p < 0:
            pos[:, j] = trans
            rots.append(local)
        else:
            pos[:, j] = pos[:, p] + rots[p].apply(trans)
            rots.append(rots[p] * local)
    return pos


def _skeleton_for(path: Path, data: BvhData) -> tuple[Skeleton, np.ndarray | None]:
    """CMU-31 (with the joint permutation into ASF order) when names match its aliases, else the file's own."""
    if sorted(data.names) == sorted(CMU31_BVH_ALIASES):
        order = np.array([data.names.index(a) for a in CMU31_BVH_ALIASES])
        sk = cmu31()
        parents_ok = all(
            (data.parents[order[i]] == -1 and p == -1) or (p >= 0 and data.parents[order[i]] == order[p])
            for i, p in enumerate(sk.parents)
        )
        if parents_ok:
            return sk, order
        _log.info("%s: CMU joint names but a different hierarchy; keeping the file's skeleton", path)
    try:
        sk = Skeleton(name=path.stem, joint_names=tuple(data.names), parents=tuple(data.parents))
    except ValueError:
        sk = Skeleton(
            name=path.stem,
            joint_names=tuple(data.names),
            parents=tuple(data.parents),
            mirror=tuple(range(len(data.names))),
        )
    return sk, None


def guess_scale_m(positions: np.ndarray, up: int) -> tuple[float, str]:
    """Metres per file unit of a human figure, from its height (heuristic in the module docstring).

    Args:
        positions: Joint positions in file units and axes, shape ``(T, J, 3)``.
        up: Index of the file's up axis (1 for y-up BVH, 2 for z-up).

    Returns:
        ``(scale, unit)``, e.g. ``(0.01, "cm")``.

    Example:
        >>> pos = np.zeros((1, 2, 3)); pos[0, 1, 1] = 160.0
        >>> guess_scale_m(pos, up=1)
        (0.01, 'cm')
    """
    extent = float(np.percentile(np.ptp(positions[..., up], axis=1), 95))
    if not extent > 0:
        return _AUTO_UNITS["cm"], "cm"
    unit = min(_AUTO_UNITS, key=lambda u: abs(math.log(extent * _AUTO_UNITS[u] / _TYPICAL_EXTENT_M)))
    return _AUTO_UNITS[unit], unit


@register_loader("bvh", suffixes=(".bvh",))
def load_bvh(path: str | Path, *, scale: float | None = None, up_axis: str = "y") -> Motion:
    """Load a BVH file as joint positions in metres, world z-up.

    Args:
        path: BVH file.
        scale: Metres per file unit; ``None`` picks 0.0254/0.45 for CMU-31 files, else the unit
            (m, cm or mm) that gives a human height (:func:`guess_scale_m`).
        up_axis: ``"y"`` (BVH default, converted to z-up) or ``"z"`` (kept).

    Returns:
        Motion with ``positions`` of shape ``(T, J, 3)`` in metres, world z-up, and the CMU-31
        skeleton (ASF joint order) when the joint names are the CMU BVH aliases.

    Raises:
        MotionFormatError: Malformed file, one line naming file, line, expected and found.
    """
    path = Path(path)
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be 'y' or 'z', got {up_axis!r}")
    data = parse_bvh(path)
    skeleton, order = _skeleton_for(path, data)
    is_cmu = order is not None
    pos = forward_kinematics(data)
    if scale is not None:
        scale_source = "argument"
    elif is_cmu:
        scale, scale_source = CMU_BVH_SCALE_M, "cmu"
    else:
        scale, unit = guess_scale_m(pos, up=1 if up_axis == "y" else 2)
        scale_source = f"auto:{unit}"
        extent = float(np.percentile(np.ptp(pos[..., 1 if up_axis == "y" else 2], axis=1), 95)) * scale
        lo, hi = _PLAUSIBLE_EXTENT_M
        if not lo <= extent <= hi:
            warnings.warn(
                f"{path}: figure height {extent:.2f} m with the guessed unit {unit!r} is outside "
                f"{lo}-{hi} m; pass scale (metres per file unit) if the file is not in m, cm or mm",
                stacklevel=3,
            )
        _log.info("%s: no scale given; file units read as %s (figure height %.2f m)", path, unit, extent)
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be > 0 metres per unit, got {scale}")
    pos = pos * scale
    if order is not None:
        pos = pos[:, order]
    if up_axis == "y":
        pos = np.stack([pos[..., 0], -pos[..., 2], pos[..., 1]], axis=-1)
    fps = 1.0 / data.frame_time_s
    if abs(fps - round(fps)) < 1e-4 * fps:  # headers print 1/120 as .0083333: snap to 120 Hz
        fps = float(round(fps))
    return Motion(
        positions=pos,
        fps_hz=fps,
        skeleton=skeleton,
        name=path.stem,
        provenance={
            "path": str(path),
            "format": "bvh",
            "scale_m_per_unit": scale,
            "scale_source": scale_source,
            "up_axis": up_axis,
            "frame_time_s": data.frame_time_s,
            "cmu31": is_cmu,
            "rest_stature_m": rest_stature(data, up=1 if up_axis == "y" else 2) * scale,
        },
    )
