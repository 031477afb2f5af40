"""Topology augmentations: random joint subsets, merged joints and markers offset from the joints.

Each one maps a motion onto a new skeleton by a fixed linear map of its joints: new joint i is
``sum_j W[i, j] * old joint j`` with one weight matrix for the whole motion, so the new "joints"
move as rigidly as the old ones did. With them no two training samples need share a topology.

A new joint keeps an *anchor* (the old joint it stands for); its parent is the new joint anchored at
the nearest ancestor of that anchor, so the new skeleton is again a tree over the same body. The
new skeleton is named after the old one with a suffix (``coco17+subset``, ``cmu31+merged+markers``),
so :func:`gttdata.skeletons.skeleton_family` still finds its family.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from gttdata.augment.registry import fires, register_augmentation
from gttdata.mocap.motion import Motion
from gttdata.skeleton import Skeleton

__all__ = [
    "TopologyMap",
    "joint_subset",
    "marker_map",
    "marker_offsets",
    "merge_joints",
    "merge_map",
    "subset_map",
]


@dataclass(frozen=True)
class TopologyMap:
    """A linear map from one skeleton's joints to another's.

    Args:
        weights: ``W``, shape ``(J_new, J_old)``; each row sums to 1.
        skeleton: The new topology (J_new joints).
    """

    weights: np.ndarray
    skeleton: Skeleton

    def apply(self, positions: np.ndarray) -> np.ndarray:
        """New joints from old, ``(..., J_old, 3)`` -> ``(..., J_new, 3)``."""
        return np.einsum("ij,...jc->...ic", self.weights, positions)

    def __call__(self, motion: Motion) -> Motion:
        """The same motion on the new skeleton (positions mapped by :meth:`apply`)."""
        return replace(motion, positions=self.apply(motion.positions), skeleton=self.skeleton)


def _build(
    sk: Skeleton, groups: list[tuple[int, ...]], weights: list[np.ndarray], names, suffix
) -> TopologyMap:
    """A TopologyMap from new joints given as (anchor first) groups of old joints and their weights."""
    n_old = sk.n_joints
    anchor_of = {g[0]: i for i, g in enumerate(groups)}
    parents = []
    for g in groups:
        p = sk.parents[g[0]]
        while p >= 0 and p not in anchor_of:
            p = sk.parents[p]
        parents.append(anchor_of[p] if p >= 0 else -1)
    by_set = {frozenset(g): i for i, g in enumerate(groups)}
    mirror = tuple(by_set.get(frozenset(sk.mirror[j] for j in g), i) for i, g in enumerate(groups))
    # A pair must map to each other (involution); anything else stays on its own.
    mirror = tuple(m if mirror[m] == i else i for i, m in enumerate(mirror))
    extra = tuple(
        (anchor_of[a], anchor_of[b]) for a, b in sk.extra_bones if a in anchor_of and b in anchor_of
    )
    W = np.zeros((len(groups), n_old))
    for i, (g, w) in enumerate(zip(groups, weights, strict=True)):
        W[i, list(g)] = w
    new = Skeleton(
        name=f"{sk.name}+{suffix}",
        joint_names=tuple(names),
        parents=tuple(parents),
        mirror=mirror,
        extra_bones=extra,
    )
    return TopologyMap(W, new)


def subset_map(sk: Skeleton, rng: np.random.Generator, *, min_keep: float = 0.5) -> TopologyMap:
    """Keep a random subset of the joints (at least ``ceil(min_keep * J)`` and 3), in their order.

    The root-most joint is always kept, so the subset stays one tree when the skeleton was one.
    """
    J = sk.n_joints
    lo = min(J, max(3, int(np.ceil(min_keep * J))))
    k = int(rng.integers(lo, J + 1))
    roots = [i for i, p in enumerate(sk.parents) if p < 0]
    rest = np.array([i for i in range(J) if i not in roots])
    extra = max(0, k - len(roots))
    keep = sorted(roots + rng.choice(rest, size=min(extra, len(rest)), replace=False).tolist())
    return _build(
        sk, [(i,) for i in keep], [np.ones(1)] * len(keep), [sk.joint_names[i] for i in keep], "subset"
    )


def merge_map(sk: Skeleton, rng: np.random.Generator, *, max_merged: float = 0.25) -> TopologyMap:
    """Merge 1 to ``max(1, max_merged * J)`` random joints into their parents (at the midpoint)."""
    J = sk.n_joints
    children = [i for i, p in enumerate(sk.parents) if p >= 0]
    n = int(rng.integers(1, max(1, int(max_merged * J)) + 1))
    picked = set(rng.choice(children, size=min(n, len(children)), replace=False).tolist())
    members: dict[int, list[int]] = {}
    for i in range(J):
        if i in picked:
            continue
        members[i] = [i]
    for c in sorted(picked):
        p = sk.parents[c]
        while p in picked:  # a chain of merged joints collapses into the first unmerged ancestor
            p = sk.parents[p]
        if p < 0:
            members[c] = [c]
        else:
            members[p].append(c)
    order = sorted(members)
    groups = [tuple(members[i]) for i in order]
    weights = [np.full(len(g), 1.0 / len(g)) for g in groups]
    names = ["&".join(sk.joint_names[j] for j in g) for g in groups]
    return _build(sk, groups, weights, names, "merged")


def marker_map(sk: Skeleton, rng: np.random.Generator, *, max_frac: float = 0.25) -> TopologyMap:
    """Replace every joint by a marker slid along its adjacent bones.

    Marker i sits at ``joint + a (parent - joint) + c (child - joint)`` with ``a, c`` uniform in
    ``[0, max_frac]`` (``a = 0`` for a root, ``c = 0`` for a leaf; ``child`` is the first child), like
    a skin marker placed near, not on, the joint centre. Markers stay on the bone axes.
    """
    J = sk.n_joints
    first_child: dict[int, int] = {}
    for i, p in enumerate(sk.parents):
        if p >= 0:
            first_child.setdefault(p, i)
    groups, weights = [], []
    for i in range(J):
        g, w = [i], [1.0]
        a, c = rng.uniform(0.0, max_frac, 2)
        if sk.parents[i] >= 0:
            g.append(sk.parents[i])
            w.append(a)
        if i in first_child:
            g.append(first_child[i])
            w.append(c)
        w[0] = 1.0 - sum(w[1:])
        groups.append(tuple(g))
        weights.append(np.array(w))
    # Groups of different joints can coincide as sets (a two-joint chain): anchors stay distinct.
    names = [f"{n}_marker" for n in sk.joint_names]
    m = _build(sk, groups, weights, names, "markers")
    return replace(m, skeleton=replace(m.skeleton, mirror=sk.mirror))


@register_augmentation("joint_subset", level="motion", ranges={"prob": (0, 1), "min_keep": (0, 1)})
def joint_subset(
    motion: Motion, rng: np.random.Generator, *, prob: float = 1.0, min_keep: float = 0.5
) -> Motion:
    """With probability ``prob``, keep a random subset of the joints (see :func:`subset_map`).

    Nothing is drawn when ``prob`` is 0, so recipes without it keep their random streams.
    """
    if not fires(rng, prob):
        return motion
    return subset_map(motion.skeleton, rng, min_keep=min_keep)(motion)


@register_augmentation("merge_joints", level="motion", ranges={"prob": (0, 1), "max_merged": (0, 1)})
def merge_joints(
    motion: Motion, rng: np.random.Generator, *, prob: float = 1.0, max_merged: float = 0.25
) -> Motion:
    """With probability ``prob``, merge random joints into their parents (see :func:`merge_map`)."""
    if not fires(rng, prob):
        return motion
    return merge_map(motion.skeleton, rng, max_merged=max_merged)(motion)


@register_augmentation("marker_offsets", level="motion", ranges={"prob": (0, 1), "max_frac": (0, 0.5)})
def marker_offsets(
    motion: Motion, rng: np.random.Generator, *, prob: float = 1.0, max_frac: float = 0.25
) -> Motion:
    """With probability ``prob``, replace the joints by markers offset along the bones (see :func:`marker_map`)."""
    if not fires(rng, prob):
        return motion
    return marker_map(motion.skeleton, rng, max_frac=max_frac)(motion)
