"""The keypoint sets of the 2-D detectors Pose2Sim and anipose users run, registered by name.

These topologies are read from detector files, never simulated: OpenPose ``BODY_25B``, ``BODY_135`` and
``COCO`` (18 points), AlphaPose / MMPose ``HALPE_68`` and ``HALPE_136``, MMPose / RTMPose whole body
``COCO_133`` and MediaPipe BlazePose (33 points). ``BODY_25``, ``COCO_17``, ``HALPE_26`` and ``HAND_21``
live in :mod:`gttdata.skeletons` (they can also be simulated).

Joint order is the tool's output order. Joint names follow Pose2Sim's ``skeletons.py`` where Pose2Sim
names the point (``Neck`` and ``Head`` for BODY_25B's upper neck and head top, ``LThumb``, ``LIndex``,
``LPinky``, ``Jaw1``...), so a TRC written from them carries the marker names of Pose2Sim's OpenSim
models; points Pose2Sim leaves unnamed get names of the same pattern (``LThumb1``, ``LMiddle2``,
``LHandRoot`` for a whole-body model's hand-root point). BlazePose keeps MediaPipe's own names
(``left_foot_index``); :func:`trc_marker_names` gives Pose2Sim's names for the TRC.

Example:
    >>> from gttdata.skeletons import get_skeleton
    >>> sk = get_skeleton("BODY_25B")
    >>> sk.joint_names[17], sk.joint_names[18], sk.n_joints
    ('Neck', 'Head', 25)
"""

from __future__ import annotations

from pathlib import Path

from gttdata.skeleton import Skeleton

__all__ = [
    "AMBIGUOUS_COUNTS",
    "DETECTOR_SKELETONS",
    "POSE2SIM_MODELS",
    "dlc_project_edges",
    "pose2sim_model",
    "skeleton_from_edges",
    "trc_marker_names",
]

_FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")

#: Body of COCO-17 in Pose2Sim's names (COCO keypoint order).
_COCO17_P2S: tuple[str, ...] = (
    "Nose", "LEye", "REye", "LEar", "REar", "LShoulder", "RShoulder", "LElbow", "RElbow",
    "LWrist", "RWrist", "LHip", "RHip", "LKnee", "RKnee", "LAnkle", "RAnkle",
)  # fmt: skip

#: HALPE-26 in Pose2Sim's names (AlphaPose order).
_HALPE26_P2S: tuple[str, ...] = _COCO17_P2S + (
    "Head", "Neck", "Hip", "LBigToe", "RBigToe", "LSmallToe", "RSmallToe", "LHeel", "RHeel",
)  # fmt: skip

#: BODY_25B in Pose2Sim's names (OpenPose order: COCO-17, upper neck, head top, feet).
BODY25B_JOINTS: tuple[str, ...] = _COCO17_P2S + (
    "Neck", "Head", "LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel",
)  # fmt: skip

#: OpenPose COCO (18 points) in OpenPose's / Pose2Sim's names.
COCO18_JOINTS: tuple[str, ...] = (
    "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist",
    "RHip", "RKnee", "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar",
)  # fmt: skip

#: Face (68 points, iBUG order) in Pose2Sim's names: jaw, right then left eyebrow, nose, eyes, mouth.
FACE68: tuple[str, ...] = (
    tuple(f"Jaw{k}" for k in range(1, 18))
    + tuple(f"EyebrowR{k}" for k in range(1, 6))
    + tuple(f"EyebrowL{k}" for k in range(1, 6))
    + tuple(f"Nose{k}" for k in range(1, 10))
    + tuple(f"REye{k}" for k in range(1, 7))
    + tuple(f"LEye{k}" for k in range(1, 7))
    + tuple(f"Mouth{k}" for k in range(1, 21))
)

#: MediaPipe BlazePose (33 points) in MediaPipe's names and order.
BLAZEPOSE33_JOINTS: tuple[str, ...] = (
    "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye",
    "right_eye_outer", "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_pinky",
    "right_pinky", "left_index", "right_index", "left_thumb", "right_thumb", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle", "left_heel", "right_heel",
    "left_foot_index", "right_foot_index",
)  # fmt: skip


def _hand(side: str, with_root: bool) -> tuple[str, ...]:
    """Hand points of one side: the hand root (if any), then 4 per finger from base to tip.

    Pose2Sim's whole-body skeletons call the thumb's second point ``LThumb`` and the index's and pinky's
    first ``LIndex``/``LPinky``; the rest follow ``LThumb1``...``LPinky4``.
    """
    rename = {
        f"{side}Thumb2": f"{side}Thumb",
        f"{side}Index1": f"{side}Index",
        f"{side}Pinky1": f"{side}Pinky",
    }
    pts = tuple(rename.get(f"{side}{f}{k}", f"{side}{f}{k}") for f in _FINGERS for k in range(1, 5))
    return ((f"{side}HandRoot",) if with_root else ()) + pts


def _hand20_body135(side: str) -> tuple[str, ...]:
    """BODY_135's 20 hand points of one side (no hand root), with Pose2Sim's names at its indices.

    Pose2Sim names BODY_135's points 27, 30, 42 ``LThumb``, ``LIndex``, ``LPinky`` (third thumb, second
    index and pinky points) and 48, 51, 63 ``RThumb``, ``RIndex``, ``RPinky`` (one point further along
    each right finger); those indices are kept so a TRC's markers are the ones Pose2Sim's model expects.
    """
    rename = {
        "L": {"LThumb3": "LThumb", "LIndex2": "LIndex", "LPinky2": "LPinky"},
        "R": {"RThumb4": "RThumb", "RIndex3": "RIndex", "RPinky3": "RPinky"},
    }[side]
    return tuple(rename.get(f"{side}{f}{k}", f"{side}{f}{k}") for f in _FINGERS for k in range(1, 5))


HALPE68_JOINTS: tuple[str, ...] = _HALPE26_P2S + _hand("L", True) + _hand("R", True)
HALPE136_JOINTS: tuple[str, ...] = _HALPE26_P2S + FACE68 + _hand("L", True) + _hand("R", True)
COCO133_JOINTS: tuple[str, ...] = (
    _COCO17_P2S
    + ("LBigToe", "LSmallToe", "LHeel", "RBigToe", "RSmallToe", "RHeel")
    + FACE68
    + _hand("L", True)
    + _hand("R", True)
)
BODY135_JOINTS: tuple[str, ...] = (
    BODY25B_JOINTS + _hand20_body135("L") + _hand20_body135("R") + FACE68 + ("RPupil", "LPupil")
)


def _body_edges(names: tuple[str, ...], neck: str, hip: str | None) -> dict[str, str | None]:
    """Tree of the body points present in ``names`` (Pose2Sim names), rooted at ``neck``.

    The head chain is neck -> (Head ->) Nose -> eyes -> ears; arms hang from the neck; legs from
    ``hip`` (a mid-hip point) when there is one, else from the neck; feet from the ankles.
    """
    have = set(names)
    e: dict[str, str | None] = {neck: None}
    if "Head" in have:
        e |= {"Head": neck, "Nose": "Head"}
    else:
        e["Nose"] = neck
    if hip is not None:
        e[hip] = neck
    for s in ("L", "R"):
        e |= {f"{s}Shoulder": neck, f"{s}Elbow": f"{s}Shoulder", f"{s}Wrist": f"{s}Elbow"}
        e |= {f"{s}Hip": hip or neck, f"{s}Knee": f"{s}Hip", f"{s}Ankle": f"{s}Knee"}
        e |= {f"{s}Eye": "Nose", f"{s}Ear": f"{s}Eye"}
        e |= {f"{s}BigToe": f"{s}Ankle", f"{s}SmallToe": f"{s}BigToe", f"{s}Heel": f"{s}Ankle"}
    return {k: v for k, v in e.items() if k in have}


def _hand_edges(names: tuple[str, ...], side: str) -> dict[str, str | None]:
    """Each finger a chain from the hand root (or the body wrist when there is none)."""
    root = f"{side}HandRoot" if f"{side}HandRoot" in names else f"{side}Wrist"
    e: dict[str, str | None] = {f"{side}HandRoot": f"{side}Wrist"} if root != f"{side}Wrist" else {}
    chain_names = [n for n in names if n.startswith(tuple(f"{side}{f}" for f in _FINGERS))]
    for f in _FINGERS:
        chain = [n for n in chain_names if n.startswith(f"{side}{f}")]
        prev = root
        for n in chain:
            e[n] = prev
            prev = n
    return e


def _build(name: str, joints: tuple[str, ...], neck: str, hip: str | None) -> Skeleton:
    e = _body_edges(joints, neck, hip)
    for s in ("L", "R"):
        e |= _hand_edges(joints, s)
    anchor = "Nose"
    for n in joints:
        if n not in e:  # face points hang from the nose (a star: drawn, not a kinematic chain)
            e[n] = anchor
    idx = {n: i for i, n in enumerate(joints)}
    parents = tuple(-1 if (p := e[n]) is None else idx[p] for n in joints)
    extra = [(idx[f"L{p}"], idx[f"R{p}"]) for p in ("Shoulder", "Hip") if f"L{p}" in idx and hip is None]
    return Skeleton(name=name, joint_names=joints, parents=parents, extra_bones=tuple(extra))


def body25b() -> Skeleton:
    """OpenPose BODY_25B (25 points, experimental OpenPose model; Pose2Sim's default), rooted at ``Neck``.

    Order: COCO-17, then the upper neck (``Neck``), the head top (``Head``) and six foot points. Not the
    same points as BODY_25, which has the same count: the two are never told apart by count.
    """
    return _build("body25b", BODY25B_JOINTS, "Neck", None)


def coco18() -> Skeleton:
    """OpenPose COCO (18 points: COCO-17 plus a neck, in OpenPose's order), rooted at ``Neck``."""
    return _build("coco18", COCO18_JOINTS, "Neck", None)


def body135() -> Skeleton:
    """OpenPose BODY_135: BODY_25B, 20 points per hand (no hand root), 70 face points (68 + pupils)."""
    return _build("body135", BODY135_JOINTS, "Neck", None)


def halpe68() -> Skeleton:
    """AlphaPose / MMPose HALPE_68: HALPE-26, then a 21-point left and right hand, rooted at ``Neck``."""
    return _build("halpe68", HALPE68_JOINTS, "Neck", "Hip")


def halpe136() -> Skeleton:
    """AlphaPose / MMPose HALPE_136: HALPE-26, 68 face points, then a 21-point left and right hand."""
    return _build("halpe136", HALPE136_JOINTS, "Neck", "Hip")


def coco133() -> Skeleton:
    """MMPose / RTMPose whole body COCO_133: COCO-17, 6 foot points, 68 face points, two 21-point hands.

    COCO-WholeBody has no neck point: the tree is rooted at the nose (shoulders hang from it).
    """
    joints = COCO133_JOINTS
    e = _body_edges(joints, "Nose", None)
    e.pop("Nose")
    e |= {"Nose": None}
    for s in ("L", "R"):
        e |= {f"{s}Shoulder": "Nose", f"{s}Hip": f"{s}Shoulder"}
        e |= _hand_edges(joints, s)
    for n in joints:
        e.setdefault(n, "Nose")
    idx = {n: i for i, n in enumerate(joints)}
    parents = tuple(-1 if (p := e[n]) is None else idx[p] for n in joints)
    extra = ((idx["LShoulder"], idx["RShoulder"]), (idx["LHip"], idx["RHip"]))
    return Skeleton(name="coco133", joint_names=joints, parents=parents, extra_bones=extra)


def blazepose33() -> Skeleton:
    """MediaPipe BlazePose (33 points, MediaPipe's names and order), rooted at the nose."""
    j = BLAZEPOSE33_JOINTS
    e: dict[str, str | None] = {"nose": None, "mouth_left": "nose", "mouth_right": "nose"}
    for s in ("left", "right"):
        e |= {
            f"{s}_eye_inner": "nose", f"{s}_eye": f"{s}_eye_inner", f"{s}_eye_outer": f"{s}_eye",
            f"{s}_ear": f"{s}_eye_outer", f"{s}_shoulder": "nose", f"{s}_elbow": f"{s}_shoulder",
            f"{s}_wrist": f"{s}_elbow", f"{s}_pinky": f"{s}_wrist", f"{s}_index": f"{s}_wrist",
            f"{s}_thumb": f"{s}_wrist", f"{s}_hip": f"{s}_shoulder", f"{s}_knee": f"{s}_hip",
            f"{s}_ankle": f"{s}_knee", f"{s}_heel": f"{s}_ankle", f"{s}_foot_index": f"{s}_ankle",
        }  # fmt: skip
    idx = {n: i for i, n in enumerate(j)}
    extra = ((idx["left_shoulder"], idx["right_shoulder"]), (idx["left_hip"], idx["right_hip"]))
    return Skeleton(
        name="blazepose33",
        joint_names=j,
        parents=tuple(-1 if (p := e[n]) is None else idx[p] for n in j),
        extra_bones=extra,
    )


#: Registry name -> builder of the topologies this module adds.
DETECTOR_SKELETONS = {
    "body25b": body25b,
    "body135": body135,
    "coco18": coco18,
    "halpe68": halpe68,
    "halpe136": halpe136,
    "coco133": coco133,
    "blazepose33": blazepose33,
}

#: Pose2Sim's ``pose_model`` values (Config.toml ``[pose] pose_model``) -> registry name.
POSE2SIM_MODELS: dict[str, str] = {
    "BODY_25B": "body25b",
    "BODY_25": "body25",
    "BODY_135": "body135",
    "COCO": "coco18",
    "COCO_17": "coco17",
    "BODY": "coco17",
    "COCO_133": "coco133",
    "COCO_133_WRIST": "coco133",
    "WHOLE_BODY": "coco133",
    "WHOLE_BODY_WRIST": "coco133",
    "HALPE_26": "halpe26",
    "BODY_WITH_FEET": "halpe26",
    "HALPE_68": "halpe68",
    "HALPE_136": "halpe136",
    "BLAZEPOSE": "blazepose33",
    "HAND": "hand21",
    "HAND_21": "hand21",
}

#: Joint counts two registered detector sets share: never guessed from the count.
AMBIGUOUS_COUNTS: dict[int, tuple[str, ...]] = {25: ("body25", "body25b")}


def pose2sim_model(value: str) -> str:
    """Registry name of a Pose2Sim ``pose_model`` (case-insensitive), e.g. ``"body_25b"`` -> ``"body25b"``.

    Raises:
        KeyError: An unknown model, with the known ones.
    """
    key = str(value).strip().upper().replace("-", "_")
    if key in POSE2SIM_MODELS:
        return POSE2SIM_MODELS[key]
    raise KeyError(f"unknown Pose2Sim pose_model {value!r}; expected one of {', '.join(POSE2SIM_MODELS)}")


# Pose2Sim marker names of the topologies whose joint names are another tool's.
_BODY25_P2S = {"MidHip": "CHip"}
_SNAKE_P2S = {
    "head": "Head", "neck": "Neck", "hip": "Hip", "nose": "Nose",
}  # fmt: skip


def _snake_to_p2s(name: str) -> str:
    """``left_big_toe`` -> ``LBigToe``, ``right_eye`` -> ``REye``, ``nose`` -> ``Nose``."""
    if name in _SNAKE_P2S:
        return _SNAKE_P2S[name]
    side, _, rest = name.partition("_")
    prefix = {"left": "L", "right": "R"}.get(side)
    if prefix is None:
        return "".join(p.capitalize() for p in name.split("_"))
    return prefix + "".join(p.capitalize() for p in rest.split("_"))


def trc_marker_names(skeleton: Skeleton) -> tuple[str, ...]:
    """Marker names to write in a TRC: Pose2Sim's names for the keypoints of the tools it reads.

    BODY_25's ``MidHip`` is Pose2Sim's ``CHip``; COCO-17's, HALPE-26's and BlazePose's snake-case names
    become Pose2Sim's (``left_big_toe`` -> ``LBigToe``; BlazePose's ``left_foot_index`` -> ``LBigToe``);
    a hand's ``thumb1`` is ``RThumb1`` as in Pose2Sim's HAND_21. Other skeletons keep their joint names.

    Example:
        >>> from gttdata.skeletons import get_skeleton
        >>> trc_marker_names(get_skeleton("halpe26"))[17:20]
        ('Head', 'Neck', 'Hip')
    """
    base = skeleton.name.split("+", 1)[0]
    names = skeleton.joint_names
    if base == "body25":
        out = tuple(_BODY25_P2S.get(n, n) for n in names)
    elif base in ("coco17", "halpe26"):
        out = tuple(_snake_to_p2s(n) for n in names)
    elif base == "blazepose33":
        out = tuple(_snake_to_p2s(n.replace("foot_index", "big_toe")) for n in names)
    elif base == "hand21":
        out = tuple("RWrist" if n == "wrist" else "R" + n.capitalize() for n in names)
    else:
        out = names
    return out if len(set(out)) == len(out) else names


def skeleton_from_edges(name: str, joint_names: tuple[str, ...], edges: list[tuple[str, str]]) -> Skeleton:
    """A topology from a tool's own joint names and limb list (DeepLabCut's ``config.yaml`` ``skeleton``).

    The tree is a breadth-first spanning forest from the first joint (then from the first joint not reached);
    limbs that would close a cycle are kept as ``extra_bones``. Limbs naming unknown joints are ignored.

    Example:
        >>> sk = skeleton_from_edges("mouse", ("snout", "ear", "tail"), [("snout", "ear"), ("ear", "tail")])
        >>> sk.parents
        (-1, 0, 1)
    """
    idx = {n: i for i, n in enumerate(joint_names)}
    adj: dict[int, list[int]] = {i: [] for i in range(len(joint_names))}
    pairs = sorted(
        {(min(idx[a], idx[b]), max(idx[a], idx[b])) for a, b in edges if a in idx and b in idx and a != b}
    )
    for a, b in pairs:
        adj[a].append(b)
        adj[b].append(a)
    parents = [-2] * len(joint_names)
    tree: set[tuple[int, int]] = set()
    for root in range(len(joint_names)):
        if parents[root] != -2:
            continue
        parents[root] = -1
        queue = [root]
        while queue:
            u = queue.pop(0)
            for w in adj[u]:
                if parents[w] == -2:
                    parents[w] = u
                    tree.add((min(u, w), max(u, w)))
                    queue.append(w)
    extra = tuple(p for p in pairs if p not in tree)
    return Skeleton(name=name, joint_names=joint_names, parents=tuple(parents), extra_bones=extra)


def dlc_project_edges(source: str | Path, levels: int = 3) -> tuple[Path, list[tuple[str, str]]] | None:
    """The limb list of the DeepLabCut project a keypoint file came from, or None.

    Looks for ``config.yaml`` beside ``source`` and up to ``levels`` folders above, read as data
    (``yaml.safe_load``); it must hold ``bodyparts`` and a ``skeleton`` list of name pairs.
    """
    import yaml

    p = Path(source)
    for folder in [p.parent, *list(p.parents)[1 : levels + 1]]:
        cfg = folder / "config.yaml"
        if not cfg.is_file():
            continue
        try:
            d = yaml.safe_load(cfg.read_text())
        except (yaml.YAMLError, UnicodeDecodeError, OSError):
            return None
        if not isinstance(d, dict) or not isinstance(d.get("skeleton"), list):
            return None
        edges = [(str(e[0]), str(e[1])) for e in d["skeleton"] if isinstance(e, list | tuple) and len(e) == 2]
        return cfg, edges
    return None
