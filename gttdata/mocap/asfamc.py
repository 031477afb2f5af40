"""Acclaim ASF/AMC loader (the CMU mocap format): skeleton file plus motion file to joint positions.

Conventions (Acclaim, as used by CMU):
    * Units: ``:units length L`` means one file length unit is 1/L inch, so metres = value * 0.0254 / L
      (CMU: L = 0.45). Root translations in the AMC use the same unit. ``:units angle deg|rad``
      applies to ASF angles; the AMC's ``:DEGREES`` / ``:RADIANS`` line to motion angles.
    * A bone's ``axis ax ay az XYZ`` gives ``C`` (rotate about x, then y, then z: extrinsic ``xyz``).
      AMC values of its ``dof`` (in dof order, extrinsic) give ``M``; the bone's local rotation is
      ``C M C^-1`` and its global rotation ``G = G_parent C M C^-1``.
    * Bone ends: the root at its AMC translation (ASF ``position`` when the root has no
      translation dofs), then ``E = E_parent + G (length * direction)`` for every bone.
    * Joint positions (``joints_at``): ``"start"`` (default) puts each bone's joint where the bone
      starts (its parent's end; the root at the root), exactly as the CMU BVH conversions place
      their joints, so CMU-31 names mean the same points from either loader (``lfemur`` = hip
      centre). ``"end"`` puts it at the bone's end (``lfemur`` = knee; the tips are kept).
    * Axes: ASF is y-up; world is z-up: ``(x, y, z)_asf -> (x, -z, y)_world``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gttdata.errors import MotionFormatError
from gttdata.mocap import register_loader
from gttdata.mocap.motion import Motion
from gttdata.skeleton import CMU31_JOINTS, Skeleton, cmu31

__all__ = ["AsfBone", "AsfSkeleton", "load_amc", "parse_amc", "parse_asf"]

_DOFS = ("tx", "ty", "tz", "rx", "ry", "rz", "l")


@dataclass
class AsfBone:
    """One ASF bone (the root is a bone of zero length).

    Args:
        name: Bone name.
        direction: Unit direction in the ASF rest frame, shape ``(3,)``.
        length: Length in file units.
        axis_deg: Axis angles in degrees, shape ``(3,)``.
        axis_order: Order of the axis rotations, e.g. ``"XYZ"``.
        dofs: Degrees of freedom in AMC column order (``tx``..``rz``, ``l``).
        parent: Parent bone index (-1 for the root).
    """

    name: str
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis_deg: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dofs: tuple[str, ...] = ()
    parent: int = -1


@dataclass
class AsfSkeleton:
    """Parsed ASF: bones in parent-before-child order, root first, and the units.

    Args:
        bones: Bones, root first.
        length_unit: ``:units length`` value L (file unit = 1/L inch).
        angle_rad: True when ASF angles are in radians.
        root_position: Rest position of the root, file units, shape ``(3,)``.
    """

    bones: list[AsfBone]
    length_unit: float = 1.0
    angle_rad: bool = False
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def names(self) -> list[str]:
        """Bone names, root first."""
        return [b.name for b in self.bones]


def _floats(path: Path, lineno: int, parts: list[str], n: int, what: str) -> np.ndarray:
    if len(parts) < n:
        raise MotionFormatError(f"{path}: line {lineno}: {what} needs {n} numbers, found {len(parts)}")
    try:
        v = np.array([float(p) for p in parts[:n]])
    except ValueError:
        raise MotionFormatError(
            f"{path}: line {lineno}: {what} must be numbers, found {' '.join(parts[:n])!r}"
        ) from None
    if not np.all(np.isfinite(v)):
        raise MotionFormatError(
            f"{path}: line {lineno}: {what} must be finite, found {' '.join(parts[:n])!r}"
        )
    return v


def _sections(path: Path, text: str) -> dict[str, list[tuple[int, list[str]]]]:
    """Split the ASF into ``:keyword`` sections of (line number, tokens) rows."""
    out: dict[str, list[tuple[int, list[str]]]] = {}
    current = None
    for i, line in enumerate(text.splitlines(), start=1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        if parts[0].startswith(":"):
            current = parts[0][1:].lower()
            out[current] = [(i, parts[1:])] if len(parts) > 1 else []
        elif current is not None:
            out[current].append((i, parts))
    for key in ("root", "bonedata", "hierarchy"):
        if key not in out:
            raise MotionFormatError(f"{path}: expected an ':{key}' section, found none (truncated file?)")
    return out


def _parse_bone_block(path: Path, rows: list[tuple[int, list[str]]]) -> AsfBone:
    bone = AsfBone(name="")
    for lineno, parts in rows:
        key, rest = parts[0].lower(), parts[1:]
        if key == "name":
            bone.name = rest[0] if rest else ""
        elif key == "direction":
            bone.direction = _floats(path, lineno, rest, 3, "direction")
        elif key == "length":
            bone.length = float(_floats(path, lineno, rest, 1, "length")[0])
        elif key == "axis":
            bone.axis_deg = _floats(path, lineno, rest, 3, "axis")
            bone.axis_order = rest[3].upper() if len(rest) > 3 else "XYZ"
        elif key == "dof":
            bad = [d for d in rest if d.lower() not in _DOFS]
            if bad:
                raise MotionFormatError(f"{path}: line {lineno}: dof must be among {_DOFS}, found {bad[0]!r}")
            bone.dofs = tuple(d.lower() for d in rest)
    if not bone.name:
        raise MotionFormatError(f"{path}: line {rows[0][0] if rows else 0}: bone block has no 'name'")
    n = np.linalg.norm(bone.direction)
    if bone.length > 0 and n == 0:
        raise MotionFormatError(f"{path}: bone {bone.name!r}: direction must be non-zero, found (0, 0, 0)")
    bone.direction = bone.direction / n if n > 0 else bone.direction
    return bone


def _parse_root(path: Path, rows: list[tuple[int, list[str]]]) -> tuple[AsfBone, np.ndarray]:
    root = AsfBone(name="root", dofs=("tx", "ty", "tz", "rx", "ry", "rz"))
    position = np.zeros(3)
    for lineno, parts in rows:
        key, rest = parts[0].lower(), parts[1:]
        if key == "order":
            bad = [d for d in rest if d.lower() not in _DOFS]
            if bad:
                raise MotionFormatError(
                    f"{path}: line {lineno}: root order must be among {_DOFS}, found {bad[0]!r}"
                )
            root.dofs = tuple(d.lower() for d in rest)
        elif key == "axis":
            root.axis_order = rest[0].upper() if rest else "XYZ"
        elif key == "position":
            position = _floats(path, lineno, rest, 3, "root position")
        elif key == "orientation":
            root.axis_deg = _floats(path, lineno, rest, 3, "root orientation")
    return root, position


def _parse_units(path: Path, rows: list[tuple[int, list[str]]]) -> tuple[float, bool]:
    length_unit, angle_rad = 1.0, False
    for lineno, parts in rows:
        if parts[0].lower() == "length":
            length_unit = float(_floats(path, lineno, parts[1:], 1, "units length")[0])
            if length_unit <= 0:
                raise MotionFormatError(f"{path}: line {lineno}: units length must be > 0, found {parts[1]}")
        elif parts[0].lower() == "angle":
            angle_rad = len(parts) > 1 and parts[1].lower().startswith("rad")
    return length_unit, angle_rad


def _parse_bonedata(path: Path, rows: list[tuple[int, list[str]]]) -> dict[str, AsfBone]:
    bones: dict[str, AsfBone] = {}
    block: list[tuple[int, list[str]]] | None = None
    for lineno, parts in rows:
        if parts[0].lower() == "begin":
            block = []
        elif parts[0].lower() == "end":
            if block is None:
                raise MotionFormatError(f"{path}: line {lineno}: expected 'begin' before 'end'")
            b = _parse_bone_block(path, block)
            bones[b.name] = b
            block = None
        elif block is not None:
            block.append((lineno, parts))
    if block is not None:
        raise MotionFormatError(f"{path}: ':bonedata' expected 'end', found end of section (truncated file?)")
    return bones


def _order_bones(
    path: Path, root: AsfBone, bones: dict[str, AsfBone], rows: list[tuple[int, list[str]]]
) -> list[AsfBone]:
    """Bones reachable from the root through ``:hierarchy``, depth first, with parent indices set."""
    children: dict[str, list[str]] = {}
    for lineno, parts in rows:
        if parts[0].lower() in ("begin", "end"):
            continue
        for name in parts:
            if name != "root" and name not in bones:
                raise MotionFormatError(f"{path}: line {lineno}: hierarchy names unknown bone {name!r}")
        children.setdefault(parts[0], []).extend(parts[1:])
    ordered = [root]
    stack = [(c, 0) for c in reversed(children.get("root", []))]
    while stack:
        name, parent = stack.pop()
        if any(b.name == name for b in ordered):
            raise MotionFormatError(f"{path}: ':hierarchy' reaches bone {name!r} twice; expected a tree")
        bone = bones[name]
        bone.parent = parent
        ordered.append(bone)
        stack.extend((c, len(ordered) - 1) for c in reversed(children.get(name, [])))
    return ordered


def parse_asf(path: str | Path) -> AsfSkeleton:
    """Parse an ASF skeleton file.

    Raises:
        MotionFormatError: Missing section, bad number, unknown bone in the hierarchy.
    """
    path = Path(path)
    sec = _sections(path, path.read_text(errors="replace"))
    length_unit, angle_rad = _parse_units(path, sec.get("units", []))
    root, position = _parse_root(path, sec["root"])
    bones = _parse_bonedata(path, sec["bonedata"])
    if angle_rad:
        root.axis_deg = np.rad2deg(root.axis_deg)
        for b in bones.values():
            b.axis_deg = np.rad2deg(b.axis_deg)
    ordered = _order_bones(path, root, bones, sec["hierarchy"])
    return AsfSkeleton(bones=ordered, length_unit=length_unit, angle_rad=angle_rad, root_position=position)


def parse_amc(path: str | Path, skeleton: AsfSkeleton) -> tuple[np.ndarray, bool]:
    """Parse an AMC motion file against its skeleton.

    Args:
        path: AMC file.
        skeleton: The parsed ASF.

    Returns:
        ``(values, radians)``: per-bone dof values, shape ``(T, sum of dofs)`` in bone order then dof
        order (file units and angle unit), and whether angles are in radians.

    Raises:
        MotionFormatError: Unknown bone, wrong value count, non-numeric or non-finite value, zero frames.
    """
    path = Path(path)
    cols, start = {}, 0
    for b in skeleton.bones:
        cols[b.name] = (start, len(b.dofs))
        start += len(b.dofs)
    frames: list[np.ndarray] = []
    radians = False
    current = None
    for lineno, line in enumerate(path.read_text(errors="replace").splitlines(), start=1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        if parts[0].startswith(":"):
            radians = radians or parts[0].upper() == ":RADIANS"
            continue
        if len(parts) == 1 and re.fullmatch(r"\d+", parts[0]):
            current = np.full(start, np.nan)
            frames.append(current)
            continue
        name = parts[0]
        if current is None:
            raise MotionFormatError(f"{path}: line {lineno}: expected a frame number, found {name!r}")
        if name not in cols:
            raise MotionFormatError(
                f"{path}: line {lineno}: unknown joint {name!r} (not in the ASF skeleton)"
            )
        c0, n = cols[name]
        if len(parts) - 1 != n:
            raise MotionFormatError(
                f"{path}: line {lineno}: {name} expects {n} values, found {len(parts) - 1} (truncated line?)"
            )
        current[c0 : c0 + n] = _floats(path, lineno, parts[1:], n, f"{name} values")
    if not frames:
        raise MotionFormatError(f"{path}: found zero frames; expected at least 1")
    values = np.stack(frames)
    missing = np.isnan(values)
    if missing.any():
        t, c = np.argwhere(missing)[0]
        bone = next(b for b, (c0, n) in cols.items() if c0 <= c < c0 + n)
        raise MotionFormatError(
            f"{path}: frame {t + 1}: joint {bone!r} has no values; expected every frame to list it "
            "(truncated file?)"
        )
    return values, radians


def _forward_kinematics(sk: AsfSkeleton, values: np.ndarray, radians: bool) -> np.ndarray:
    """Joint positions (root, then bone ends), shape ``(T, J, 3)``, file units, ASF axes."""
    T = values.shape[0]
    pos = np.zeros((T, len(sk.bones), 3))
    rots: list[Rotation] = []
    col = 0
    for j, b in enumerate(sk.bones):
        v = values[:, col : col + len(b.dofs)]
        col += len(b.dofs)
        trans = np.broadcast_to(sk.root_position, (T, 3)).copy()
        length = np.full(T, b.length)
        axes, angles = "", []
        for k, d in enumerate(b.dofs):
            if d[0] == "t":
                trans[:, "xyz".index(d[1])] = v[:, k]
            elif d == "l":
                length = length + v[:, k]
            else:
                axes += d[1]
                angles.append(v[:, k])
        motion = (
            Rotation.from_euler(axes, np.stack(angles, axis=1), degrees=not radians)
            if axes
            else Rotation.identity(T)
        )
        # Lower-case axes: extrinsic, i.e. rotate about the first listed axis first (Acclaim).
        C = Rotation.from_euler(b.axis_order.lower(), b.axis_deg, degrees=True)
        local = C * motion * C.inv()
        if b.parent < 0:
            rots.append(local)
            pos[:, j] = trans
        else:
            rots.append(rots[b.parent] * local)
            pos[:, j] = pos[:, b.parent] + rots[j].apply(b.direction) * length[:, None]
    return pos


def _find_asf(path: Path) -> Path:
    subject = path.parent / f"{path.stem.split('_')[0]}.asf"
    if subject.is_file():
        return subject
    found = sorted(path.parent.glob("*.asf"))
    if len(found) == 1:
        return found[0]
    raise MotionFormatError(
        f"{path}: cannot find its ASF skeleton; expected {subject.name} or a single .asf beside it, "
        f"found {len(found)}; pass asf_path"
    )


def _skeleton_for(asf: Path, sk: AsfSkeleton) -> tuple[Skeleton, list[int] | None]:
    """CMU-31 (and the permutation into its order) when names and tree match it, else the file's own."""
    names, parents = sk.names, [b.parent for b in sk.bones]
    if sorted(names) == sorted(CMU31_JOINTS):
        order = [names.index(n) for n in CMU31_JOINTS]
        cmu = cmu31()
        if all(parents[order[i]] == (order[p] if p >= 0 else -1) for i, p in enumerate(cmu.parents)):
            return cmu, order
    try:
        return Skeleton(name=asf.stem, joint_names=tuple(names), parents=tuple(parents)), None
    except ValueError:  # names whose left/right swap is not an involution: no mirror map
        return Skeleton(asf.stem, tuple(names), tuple(parents), mirror=tuple(range(len(names)))), None


@register_loader("amc", suffixes=(".amc",))
def load_amc(
    path: str | Path,
    *,
    asf_path: str | Path | None = None,
    fps_hz: float = 120.0,
    up_axis: str = "y",
    joints_at: str = "start",
) -> Motion:
    """Load an AMC motion with its ASF skeleton as joint positions in metres, world z-up.

    Args:
        path: AMC file.
        asf_path: ASF file; by default ``<subject>.asf`` beside the AMC (``01_02.amc`` -> ``01.asf``)
            or the only ``.asf`` there.
        fps_hz: Frame rate (AMC files do not store it; CMU records at 120 Hz).
        up_axis: ``"y"`` (ASF default, converted to z-up) or ``"z"`` (kept).
        joints_at: ``"start"`` (as CMU BVH files) or ``"end"`` of each bone; see the module docstring.

    Returns:
        Motion with ``positions`` of shape ``(T, J, 3)`` in metres, world z-up; J = 1 + number of
        bones, with the CMU-31 skeleton when the bone names are CMU's.
    """
    path = Path(path)
    if up_axis not in ("y", "z"):
        raise ValueError(f"up_axis must be 'y' or 'z', got {up_axis!r}")
    if joints_at not in ("start", "end"):
        raise ValueError(f"joints_at must be 'start' or 'end', got {joints_at!r}")
    asf = Path(asf_path) if asf_path is not None else _find_asf(path)
    if not asf.is_file():
        raise FileNotFoundError(2, "ASF file not found", str(asf))
    sk = parse_asf(asf)
    values, radians = parse_amc(path, sk)
    scale = 0.0254 / sk.length_unit
    pos = _forward_kinematics(sk, values, radians) * scale
    if joints_at == "start":
        parents = [max(b.parent, 0) for b in sk.bones]  # the root starts at itself
        pos = pos[:, parents]
    skeleton, order = _skeleton_for(asf, sk)
    if order is not None:
        pos = pos[:, order]
    if up_axis == "y":
        pos = np.stack([pos[..., 0], -pos[..., 2], pos[..., 1]], axis=-1)
    if not math.isfinite(fps_hz) or fps_hz <= 0:
        raise ValueError(f"fps_hz must be > 0, got {fps_hz}")
    return Motion(
        positions=pos,
        fps_hz=float(fps_hz),
        skeleton=skeleton,
        name=path.stem,
        provenance={
            "path": str(path),
            "format": "amc",
            "asf_path": str(asf),
            "scale_m_per_unit": scale,
            "up_axis": up_axis,
            "joints_at": joints_at,
        },
    )
