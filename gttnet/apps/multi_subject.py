"""Two subjects without identity across images: virtual images, affinity clustering, merge and refinement."""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from gttdata.capture.views import Observations
from gttdata.skeleton import Skeleton

__all__ = [
    "MultiSubjectResult",
    "hide_identities",
    "virtual_images",
    "cluster_subjects",
    "reconstruct_subjects",
    "score_subjects",
    "reconstruct_loaded_subjects",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MultiSubjectResult:
    """Per-subject trajectories recovered from images holding two unidentified subjects.

    Args:
        points3d: Joints of subject ``c`` (cluster ``c``) in image ``n``, metres, shape ``(N, S, P, 3)``.
        labels: Cluster of the ``k``-th joint block of image ``n`` in the input layout, shape ``(N, S)``.
        points3d_virtual: Step-2 reconstruction merged per image (before refinement), ``(N, S, P, 3)``.
        affinity: Affinity of the refinement over the N images, ``(N, N)``, or None without refinement.
        affinity_virtual: Affinity over the ``S * N`` virtual images (image ``n``, block ``k`` at ``n*S + k``).
        seconds: Wall-clock time of the five steps, s.
    """

    points3d: np.ndarray
    labels: np.ndarray
    points3d_virtual: np.ndarray
    affinity: np.ndarray | None
    affinity_virtual: np.ndarray
    seconds: float


def _block_perm(perm: np.ndarray, p: int) -> np.ndarray:
    """Joint index permutation ``(N, S*P)`` putting block ``perm[n, k]`` at position ``k``."""
    return (perm[:, :, None] * p + np.arange(p)[None, None, :]).reshape(perm.shape[0], -1)


def _reorder(obs: Observations, idx: np.ndarray) -> Observations:
    take = np.arange(obs.n_images)[:, None]
    return dataclasses.replace(obs, keypoints_px=obs.keypoints_px[take, idx], visible=obs.visible[take, idx])


def hide_identities(
    obs: Observations, *, n_subjects: int = 2, seed: int = 0
) -> tuple[Observations, np.ndarray]:
    """Shuffle, per image, which subject's joint block comes first, so the layout carries no identity.

    Args:
        obs: Observations whose ``S * P`` joints stack S subjects (block ``s`` = subject ``s``).
        n_subjects: S.
        seed: Seed of the per-image block permutations.

    Returns:
        ``(shuffled, subject)``: ``subject[n, k]`` is the true subject of block ``k`` of image ``n``,
        shape ``(N, S)`` (for scoring only; never give it to a solver).
    """
    n, j = obs.n_images, obs.n_joints
    if j % n_subjects:
        raise ValueError(f"{j} joints do not split into {n_subjects} subjects")
    rng = np.random.default_rng(seed)
    subject = np.stack([rng.permutation(n_subjects) for _ in range(n)])
    return _reorder(obs, _block_perm(subject, j // n_subjects)), subject


def _sub_skeleton(sk: Skeleton, p: int) -> Skeleton:
    names = tuple(n.split("_", 1)[1] if n[:2] == "a_" else n for n in sk.joint_names[:p])
    mirror = tuple(m if m < p else i for i, m in enumerate(sk.mirror[:p]))
    return Skeleton(
        name=sk.name.split("x")[0] or sk.name, joint_names=names, parents=sk.parents[:p], mirror=mirror
    )


def virtual_images(obs: Observations, *, n_subjects: int = 2) -> Observations:
    """Step 1: one virtual image per subject block (same camera), ``S * N`` images of ``P`` joints.

    Virtual image ``n * S + k`` holds block ``k`` of image ``n``. The result has sequencing ``none``:
    a camera's stream of virtual images interleaves subjects, so stream order says nothing.
    """
    n, s = obs.n_images, n_subjects
    p = obs.n_joints // s
    rep = np.repeat(np.arange(n), s)
    return Observations(
        sequencing="none",
        skeleton=_sub_skeleton(obs.skeleton, p),
        cam_id=obs.cam_id[rep],
        K=obs.K[rep],
        cam_from_world=obs.cam_from_world[rep],
        keypoints_px=obs.keypoints_px.reshape(n, s, p, 2).reshape(n * s, p, 2),
        visible=obs.visible.reshape(n, s, p).reshape(n * s, p),
        image_size=obs.image_size,
    )


def _signed_modes(S: np.ndarray, pairs: np.ndarray, beta: float, d: int) -> np.ndarray:
    """The ``d`` smallest generalised eigenvectors of ``(D_S - S) + beta (D_C + C)`` over ``D_S + beta D_C``."""
    m = S.shape[0]
    C = np.zeros((m, m))
    C[pairs[:, 0], pairs[:, 1]] = C[pairs[:, 1], pairs[:, 0]] = beta
    deg, cdeg = S.sum(axis=1), C.sum(axis=1)
    L = np.diag(deg) - S + np.diag(cdeg) + C
    d = max(1, min(d, m))
    _, vec = scipy.linalg.eigh(L, np.diag(deg + cdeg + 1e-12), subset_by_index=[0, d - 1])
    return vec


def _paired_two_means(U0: np.ndarray, U1: np.ndarray, *, iters: int = 30) -> np.ndarray:
    """2-means of the rows of ``U0`` and ``U1`` where row n of each must go to different clusters.

    Returns:
        Whether block 0 of each pair joins cluster 0, shape ``(n,)`` bool (best cost over inits, one per axis).
    """
    best, best_cost = np.ones(U0.shape[0], dtype=bool), np.inf
    for axis in range(U0.shape[1]):
        first = U0[:, axis] >= U1[:, axis]
        for _ in range(iters):
            a = np.where(first[:, None], U0, U1)
            b = np.where(first[:, None], U1, U0)
            mu0, mu1 = a.mean(axis=0), b.mean(axis=0)
            keep = ((U0 - mu0) ** 2).sum(1) + ((U1 - mu1) ** 2).sum(1)
            swap = ((U0 - mu1) ** 2).sum(1) + ((U1 - mu0) ** 2).sum(1)
            new = keep <= swap
            if np.array_equal(new, first):
                break
            first = new
        cost = float(np.minimum(keep, swap).sum())
        if cost < best_cost:
            best, best_cost = first, cost
    return best


def cluster_subjects(
    affinity: np.ndarray,
    n_images: int,
    *,
    features: np.ndarray | None = None,
    cannot_link_weight: float = 1.0,
    n_modes: int = 6,
) -> np.ndarray:
    """Step 3: two clusters of the virtual images, an image's two virtual images always apart.

    In each connected piece of the graph (affinity edges plus one cannot-link per image) the images are
    embedded by the ``n_modes`` smallest generalised eigenvectors of the signed Laplacian
    ``(D_A - A) + beta (D_C + C)`` over ``D_A + beta D_C`` (the quadratic form
    ``sum_ij A_ij (x_i - x_j)^2 + beta * sum_n (x_n0 + x_n1)^2``, 0 at the subject indicator when the
    affinity stays inside subjects). Slow modes along each subject's own trajectory are cheap too, so
    the indicator is found by a 2-means in that embedding with each image's two blocks kept apart. Pieces the affinity does not connect (e.g. images in which a subject
    is unseen) are aligned to the largest piece by the nearest side centroid of ``features``.

    Args:
        affinity: Affinity over the ``2N`` virtual images (image ``n`` block ``k`` at ``2n + k``).
        n_images: N.
        features: Per virtual image position, e.g. the reconstructed centroid, shape ``(2N, D)``.
        cannot_link_weight: beta relative to the mean affinity degree.
        n_modes: Embedding dimension.

    Returns:
        Cluster of each block, shape ``(N, 2)``, each row a permutation of ``(0, 1)``.
    """
    from scipy.sparse.csgraph import connected_components

    A = np.asarray(affinity, dtype=np.float64)
    m = 2 * n_images
    if A.shape != (m, m):
        raise ValueError(f"affinity must have shape ({m}, {m}), got {A.shape}")
    S = 0.5 * (np.abs(A) + np.abs(A).T)
    np.fill_diagonal(S, 0.0)
    beta = cannot_link_weight * max(float(S.sum(axis=1).mean()), 1e-12)
    G = S > 0
    G[2 * np.arange(n_images), 2 * np.arange(n_images) + 1] = True
    n_comp, comp = connected_components(G, directed=False)
    first = np.ones(n_images, dtype=bool)  # block 0 of image n on side 0
    pieces = []
    for c in range(n_comp):
        nodes = np.flatnonzero(comp == c)
        imgs = np.unique(nodes // 2)
        local = {v: i for i, v in enumerate(nodes)}
        pairs = np.array([[local[2 * n], local[2 * n + 1]] for n in imgs])
        sub = S[np.ix_(nodes, nodes)]
        if sub.any():
            U = _signed_modes(sub, pairs, beta, n_modes)
            first[imgs] = _paired_two_means(U[pairs[:, 0]], U[pairs[:, 1]])
        pieces.append(imgs)
    if features is not None and len(pieces) > 1:
        F = np.nan_to_num(np.asarray(features, dtype=np.float64).reshape(n_images, 2, -1))
        side = lambda imgs: np.where(first[imgs, None], F[imgs, 0], F[imgs, 1])  # noqa: E731
        other = lambda imgs: np.where(first[imgs, None], F[imgs, 1], F[imgs, 0])  # noqa: E731
        ref = max(pieces, key=len)
        c0, c1 = side(ref).mean(axis=0), other(ref).mean(axis=0)
        for imgs in pieces:
            if imgs is ref:
                continue
            s0, s1 = side(imgs).mean(axis=0), other(imgs).mean(axis=0)
            keep = np.linalg.norm(s0 - c0) + np.linalg.norm(s1 - c1)
            flip = np.linalg.norm(s0 - c1) + np.linalg.norm(s1 - c0)
            if flip < keep:
                first[imgs] = ~first[imgs]
    return np.stack([np.where(first, 0, 1), np.where(first, 1, 0)], axis=1)


def reconstruct_subjects(
    obs: Observations,
    *,
    n_subjects: int = 2,
    method: str = "dloe",
    refine: bool = True,
    seed: int = 0,
    **options,
) -> MultiSubjectResult:
    """The paper's five steps for two unidentified subjects per image.

    1. Virtual images per subject block; 2. reconstruct them with ``method`` (affinity included);
    3. cluster into two subjects with a cannot-link inside each image; 4. merge the two shapes of each
    image in cluster order; 5. reconstruct the N original images with the merged (cluster-ordered)
    ``S * P``-joint shape under the input's sequencing (refinement).

    Args:
        obs: Observations of ``2 * P`` joints whose block order per image carries no identity.
        n_subjects: Number of subjects (only 2 is supported).
        method: Registered method returning an affinity (``dloe``, ``pseudo``, ``gttnet``).
        refine: Run step 5.
        seed: Seed of the random order of the virtual images.
        **options: Method options (the clustering pass runs ``gttnet`` without its DLOE round).

    Returns:
        The :class:`MultiSubjectResult`.
    """
    from gttnet.methods import reconstruct

    if n_subjects != 2:
        raise ValueError(f"n_subjects: only 2 subjects are supported, got {n_subjects}")
    t0 = time.perf_counter()
    n, p = obs.n_images, obs.n_joints // n_subjects
    vobs = virtual_images(obs, n_subjects=n_subjects)
    shuffle = np.random.default_rng(seed).permutation(2 * n)  # hide the (n, k) layout from the method
    inv = np.argsort(shuffle)
    vobs = vobs.take(shuffle)
    # gttnet clusters with its learned affinity (as measured), not the weights of its DLOE round.
    vopts = {"refine": False, **options} if method == "gttnet" else options
    vrec = reconstruct(vobs, method, **vopts)
    if vrec.affinity is None:
        raise ValueError(f"method {method!r} returns no affinity; use dloe, pseudo or gttnet")
    A = vrec.affinity[np.ix_(inv, inv)]
    X = vrec.points3d[inv].reshape(n, 2, p, 3)
    labels = cluster_subjects(A, n, features=_centroids(X, vobs.visible[inv].reshape(n, 2, p)))
    merged = np.empty_like(X)
    rows = np.arange(n)
    for k in range(2):
        merged[rows, labels[:, k]] = X[:, k]
    out, aff = merged, None
    if refine:
        order = np.argsort(labels, axis=1)  # block to put at position c = the block labelled c
        robs = _reorder(obs, _block_perm(order, p))
        rrec = reconstruct(robs, method, **options)
        out, aff = rrec.points3d.reshape(n, 2, p, 3), rrec.affinity
    seconds = time.perf_counter() - t0
    log.info("two subjects: %d images in %.2f s (%s)", n, seconds, method)
    return MultiSubjectResult(out, labels, merged, aff, A, seconds)


def _centroids(X: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """Mean of the observed joints of each virtual shape (all joints when none is seen), ``(N*2, 3)``."""
    w = np.where(visible.any(axis=-1, keepdims=True), visible, True).astype(np.float64)
    return ((X * w[..., None]).sum(axis=2) / w.sum(axis=2)[..., None]).reshape(-1, 3)


def score_subjects(result: MultiSubjectResult, subject: np.ndarray, points3d_gt: np.ndarray) -> dict:
    """Clustering accuracy (best of the two label permutations) and MPJPE per subject.

    Args:
        result: Output of :func:`reconstruct_subjects`.
        subject: True subject of each block, shape ``(N, 2)`` (from :func:`hide_identities`).
        points3d_gt: Ground truth in the true subject layout, metres, shape ``(N, 2 * P, 3)``.

    Returns:
        ``{"clustering_accuracy", "mpjpe_mm": [subject 0, subject 1], "mpjpe_mm_unrefined": [...]}``.
    """
    from gttnet.evaluate.metrics import mpjpe_mm

    acc = float(np.mean(result.labels == subject))
    swap = acc < 0.5
    acc = max(acc, 1.0 - acc)
    n, _, p, _ = result.points3d.shape
    gt = np.asarray(points3d_gt).reshape(n, 2, p, 3)
    cl = [1, 0] if swap else [0, 1]  # cluster holding subject s
    return {
        "clustering_accuracy": acc,
        "mpjpe_mm": [mpjpe_mm(result.points3d[:, cl[s]], gt[:, s]) for s in range(2)],
        "mpjpe_mm_unrefined": [mpjpe_mm(result.points3d_virtual[:, cl[s]], gt[:, s]) for s in range(2)],
    }


def reconstruct_loaded_subjects(loaded, *, method: str, n_subjects: int = 2, seed: int = 0, **options):
    """``gttnet reconstruct --subjects 2``: hide identities of a loaded input, run the five steps, report.

    Args:
        loaded: A :class:`gttnet.io.LoadedInput` whose joints stack the subjects' blocks.
        method: Registered method returning an affinity.
        n_subjects: Number of subjects (2).
        seed: Seed of the per-image block shuffle.
        **options: Method options.

    Returns:
        ``(reconstruction, summary)``: points3d ``(N, 2P, 3)`` with subject ``c`` (cluster ``c``) in
        joints ``c*P .. c*P+P-1``, and a JSON-ready dict (with clustering accuracy and per-subject MPJPE
        when the input holds ground truth).
    """
    from gttnet.methods import Reconstruction

    obs, subject = hide_identities(loaded.observations, n_subjects=n_subjects, seed=seed)
    res = reconstruct_subjects(obs, n_subjects=n_subjects, method=method, seed=seed, **options)
    n = obs.n_images
    rec = Reconstruction(
        points3d=res.points3d.reshape(n, -1, 3),
        affinity=res.affinity,
        seconds=res.seconds,
        method=method,
        sequencing=obs.sequencing,
        info={"n_subjects": n_subjects},
    )
    summary = {
        "method": method,
        "sequencing": obs.sequencing,
        "n_images": n,
        "n_subjects": n_subjects,
        "seconds": round(res.seconds, 4),
    }
    if loaded.ground_truth is not None:
        sc = score_subjects(res, subject, loaded.ground_truth.points3d)
        summary["clustering_accuracy"] = round(sc["clustering_accuracy"], 4)
        summary["mpjpe_mm_per_subject"] = [round(v, 2) for v in sc["mpjpe_mm"]]
    return rec, summary
