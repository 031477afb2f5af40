"""SequenceInput: the observation-only tensors GTT-Net consumes, and their construction from Observations."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING

import numpy as np
import torch

from gttdata.capture.views import Observations

if TYPE_CHECKING:
    from gttnet.geometry.candidates import CandidatePseudoTriangulation
    from gttnet.geometry.triangulation import PseudoTriangulation

__all__ = [
    "SequenceInput",
    "order_streams",
    "pose_order",
    "prepare_inputs",
    "prepare_stream_ordered_inputs",
    "random_rotation",
    "stream_ordered_view_and_inputs",
]


@dataclass(frozen=True)
class SequenceInput:
    """Network input for one sequence: derived from observations only, never from ground truth.

    Args:
        x_init: Pseudo-triangulated structure in world, metres, shape ``(N, J, 3)`` (missing joints filled).
        nbr: Neighbourhood of each image, shape ``(N, K)`` int64, ``-1`` padded.
        centers: Camera centre per image in world, metres, shape ``(N, 3)``.
        rays: Unit viewing rays in world, shape ``(N, J, 3)``, zero where missing.
        visible: Observed joints, shape ``(N, J)`` bool.
        chain: The timing given, as an affinity of shape ``(N, N)``: under ``partial`` the within-stream
            chain (added to the learned affinity), under ``full`` the interpolation of each image between
            its time neighbours of other cameras (used by the solver instead of the learned affinity);
            None under ``none``.
        sequencing: ``"none"``, ``"partial"`` or ``"full"``.
        domain: Skeleton topology name (selects the PointNet decoder).
    """

    x_init: torch.Tensor
    nbr: torch.Tensor
    centers: torch.Tensor
    rays: torch.Tensor
    visible: torch.Tensor
    chain: torch.Tensor | None
    sequencing: str
    domain: str

    @property
    def n_images(self) -> int:
        """Number of images N."""
        return int(self.x_init.shape[0])

    def to(self, device: torch.device | str, dtype: torch.dtype | None = None) -> SequenceInput:
        """Move tensors to a device; floating tensors optionally cast to ``dtype``."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, torch.Tensor):
                v = v.to(
                    device=device, dtype=dtype if (dtype is not None and v.is_floating_point()) else None
                )
            out[f.name] = v
        return replace(self, **out)

    def rotated(self, R: torch.Tensor) -> SequenceInput:
        """The same capture with structure and cameras rotated together about the world origin.

        Neighbourhoods and the chain are rotation invariant and kept.

        Args:
            R: Rotation matrix, shape ``(3, 3)``.
        """
        R = R.to(self.x_init)
        return replace(self, x_init=self.x_init @ R.T, centers=self.centers @ R.T, rays=self.rays @ R.T)


def random_rotation(rng: np.random.Generator, *, mode: str = "so3") -> np.ndarray:
    """A random rotation: uniform on SO(3) (``"so3"``) or about the vertical z axis (``"yaw"``).

    Args:
        rng: Random generator.
        mode: ``"so3"``, ``"yaw"`` or ``"none"`` (identity).

    Returns:
        Rotation matrix, shape ``(3, 3)`` float64.
    """
    if mode == "none":
        return np.eye(3)
    if mode == "yaw":
        a = rng.uniform(0.0, 2.0 * np.pi)
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if mode != "so3":
        raise ValueError(f"rotation mode must be 'so3', 'yaw' or 'none', got {mode!r}")
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def prepare_inputs(
    obs: Observations,
    *,
    k: int,
    dtype: torch.dtype = torch.float32,
    candidates: str = "auto",
    pseudo: PseudoTriangulation | None = None,
) -> SequenceInput:
    """Pseudo-triangulate, build neighbourhoods and pack an :class:`Observations` for the network.

    The neighbourhood respects the sequencing condition (under ``none`` no stream order is used); the
    chain holds the timing that condition gives (see :class:`SequenceInput`).

    Args:
        obs: Solver inputs for one sequencing condition.
        k: Neighbours per image K.
        dtype: Floating dtype of the tensors.
        candidates: Neighbour search under ``none`` sequencing: ``"dense"`` (all pairs), ``"kdtree"``
            (epipolar-descriptor candidates, :func:`~gttnet.geometry.candidates.candidate_pseudo_triangulate`)
            or ``"auto"`` (k-d tree above :data:`~gttnet.geometry.candidates.DENSE_MAX_IMAGES` images). Other conditions use dense.
        pseudo: The dense pseudo-triangulation of these very images, to reuse instead of recomputing it
            (the reconstructor orders streams with it first); only where the dense search applies.

    Returns:
        A :class:`SequenceInput` on the CPU.
    """
    from gttnet.geometry.neighbours import chain_affinity, neighbourhoods, temporal_interpolation_affinity
    from gttnet.geometry.triangulation import pseudo_triangulate

    centers = obs.centers()
    rays = obs.rays()
    from gttnet.geometry.candidates import candidate_pseudo_triangulate, use_candidate_search

    pt: CandidatePseudoTriangulation | PseudoTriangulation
    if use_candidate_search(obs.sequencing, obs.n_images, candidates):
        if pseudo is not None:
            raise ValueError(
                "prepare_inputs: a dense pseudo-triangulation cannot be reused by the k-d tree search"
            )
        pt = candidate_pseudo_triangulate(centers, rays, obs.visible, obs.cam_id)
        nbr = pt.neighbours(k)
    else:
        if pseudo is not None and pseudo.cost.shape != (obs.n_images, obs.n_images):
            raise ValueError(
                f"prepare_inputs: pseudo holds {pseudo.cost.shape[0]} images, the capture {obs.n_images}"
            )
        pt = pseudo_triangulate(centers, rays, obs.visible, obs.cam_id) if pseudo is None else pseudo
        nbr = neighbourhoods(
            pt.cost,
            sequencing=obs.sequencing,
            cam_id=obs.cam_id,
            stream_index=obs.stream_index,
            timestamp_s=obs.timestamp_s,
            k=k,
            order=pt.order,
        )
    chain = None
    if obs.sequencing == "partial":
        assert obs.stream_index is not None  # a partial view carries its stream order
        chain = torch.as_tensor(np.asarray(chain_affinity(obs.cam_id, obs.stream_index)), dtype=dtype)
    elif obs.sequencing == "full":
        assert obs.timestamp_s is not None  # a full view carries its timestamps
        chain = torch.as_tensor(temporal_interpolation_affinity(obs.timestamp_s, obs.cam_id), dtype=dtype)
    x_init = np.nan_to_num(np.asarray(pt.X_init, dtype=np.float64))
    return SequenceInput(
        x_init=torch.as_tensor(x_init, dtype=dtype),
        nbr=torch.as_tensor(np.asarray(nbr), dtype=torch.long),
        centers=torch.as_tensor(centers, dtype=dtype),
        rays=torch.as_tensor(rays, dtype=dtype),
        visible=torch.as_tensor(obs.visible, dtype=torch.bool),
        chain=chain,
        sequencing=obs.sequencing,
        domain=obs.skeleton.name,
    )


def order_streams(obs: Observations, x_init: np.ndarray, *, k: int) -> Observations:
    """A ``partial`` view of an order-free capture, each camera's images put in the order its poses suggest.

    Without sequencing, the images of one camera are sorted by the spectral order of a k-nearest-neighbour
    graph over whole poses (:func:`~gttnet.geometry.ordering.pose_graph_affinity` of ``x_init``, e.g. the
    pseudo-triangulated structure). Within one camera consecutive frames lie several global images apart,
    so this per-stream order is far more often right than the global order it comes from; GTT-Net then
    reconstructs the view as a ``partial`` capture (stream-limited neighbourhoods and the stream chain).
    Only observations enter; the view's stream order is an estimate, not a timing the capture gave.

    The view keeps the capture's image order (a loaded ``partial`` view is grouped by camera instead; the
    network's inputs do not depend on that), so its results need no reindexing.

    Args:
        obs: An order-free capture (``sequencing == "none"``), N images.
        x_init: Poses to order the images by, shape ``(N, J, 3)``, any unit; NaN joints count as 0.
        k: Links per image of the pose graph.

    Returns:
        ``obs`` marked ``partial``, with the estimated ``stream_index`` of each image, shape ``(N,)``.

    Raises:
        ValueError: If ``obs`` is not order-free or ``x_init`` does not match it.
    """
    return _streams_view(obs, x_init, k=k)[0]


def pose_order(x: np.ndarray, *, k: int) -> np.ndarray:
    """The global image order the poses suggest: the spectral order of their k-nearest-neighbour graph.

    Args:
        x: Poses, shape ``(N, J, 3)``, any unit; NaN joints count as 0.
        k: Links per image of the pose graph (:func:`~gttnet.geometry.ordering.pose_graph_affinity`).

    Returns:
        Rank of each image, a permutation of ``0..N-1``, shape ``(N,)``.
    """
    from gttnet.geometry.ordering import pose_graph_affinity, spectral_order

    return spectral_order(
        pose_graph_affinity(np.nan_to_num(np.asarray(x, dtype=np.float64)), k=k, sparse=True)
    )


def _streams_view(obs: Observations, x_init: np.ndarray, *, k: int) -> tuple[Observations, np.ndarray]:
    """:func:`order_streams`, also returning the global rank, shape ``(N,)``, that the streams come from."""
    from gttnet.geometry.ordering import stream_ranks

    if obs.sequencing != "none":
        raise ValueError(f"order_streams: expects an order-free capture, got sequencing {obs.sequencing!r}")
    if np.shape(x_init)[0] != obs.n_images:
        raise ValueError(
            f"order_streams: x_init holds {np.shape(x_init)[0]} images, the capture {obs.n_images}"
        )
    rank = pose_order(x_init, k=k)
    return replace(obs, sequencing="partial", stream_index=stream_ranks(rank, obs.cam_id)), rank


def _quieter_streams(
    obs: Observations, view: Observations, rank: np.ndarray, cost: np.ndarray
) -> tuple[Observations, np.ndarray]:
    """The pose graph's streams, or the pseudo-triangulation partner graph's where those read as quieter.

    The partner graph links each image to the other-camera images it triangulates best with (only images
    of nearly the same pose, so nearly the same moment, do); its spectral order is right where a fast
    motion at a low frame rate makes whole poses a poor guide. A wrong order adds to the second
    differences along each stream that :func:`gttnet.geometry.noise.stream_noise_px` reads, so the order
    whose streams read as less noisy is kept.

    Args:
        obs: The order-free capture, N images.
        view: Its ``partial`` view with the pose graph's streams.
        rank: The pose graph's global rank, shape ``(N,)``.
        cost: Pseudo-triangulation cost between images, shape ``(N, N)`` (inf where not paired).

    Returns:
        ``(view, rank)`` of the kept order.
    """
    from gttnet.baselines.pseudo import top_q_affinity
    from gttnet.geometry.noise import stream_noise_px
    from gttnet.geometry.ordering import spectral_order, stream_ranks

    if obs.n_images < 3:
        return view, rank
    other = np.asarray(spectral_order(top_q_affinity(cost, q=2)))
    other_si = stream_ranks(other, obs.cam_id)
    mine = stream_noise_px(obs.keypoints_px, obs.visible, obs.cam_id, np.asarray(view.stream_index))
    theirs = stream_noise_px(obs.keypoints_px, obs.visible, obs.cam_id, other_si)
    if mine is None or theirs is None or theirs >= mine:
        return view, rank
    return replace(obs, sequencing="partial", stream_index=other_si), other


def prepare_stream_ordered_inputs(
    obs: Observations, *, k: int, order_k: int, dtype: torch.dtype = torch.float32
) -> SequenceInput:
    """Network inputs of an order-free capture reconstructed as a ``partial`` one with estimated streams.

    Pseudo-triangulates once, orders each camera's images by the poses (:func:`order_streams` with
    ``order_k`` links per image), builds the ``partial`` neighbourhoods, and weights each link of the
    within-stream chain by how alike its two pseudo-triangulated poses are
    (:func:`~gttnet.geometry.neighbours.pose_weighted_chain`): an estimated order can be wrong, and a wrong
    link between far-apart poses then fades out instead of tying two moments together.

    Args:
        obs: An order-free capture (``sequencing == "none"``).
        k: Neighbours per image K.
        order_k: Links per image of the pose graph that orders the streams.
        dtype: Floating dtype of the tensors.

    Returns:
        A :class:`SequenceInput` on the CPU, images in ``obs``'s order, ``sequencing == "partial"``.
    """
    return stream_ordered_view_and_inputs(obs, k=k, order_k=order_k, dtype=dtype)[1]


def stream_ordered_view_and_inputs(
    obs: Observations,
    *,
    k: int,
    order_k: int,
    dtype: torch.dtype = torch.float32,
    partner_order: bool = False,
) -> tuple[Observations, SequenceInput, np.ndarray]:
    """:func:`prepare_stream_ordered_inputs`, also returning the view and the global rank.

    With ``partner_order`` the streams come from the pose graph or from the pseudo-triangulation partner
    graph, whichever reads as less noisy (:func:`_quieter_streams`); the cross-domain model uses it (on its
    validation captures the sum of the means fell 5.2 %). The CMU-31 models keep the pose graph's streams
    they were trained on (there the choice changed 4 of 46 validation captures, 3 for the worse).

    Returns ``(view, inputs, rank)``: the ``partial`` view with the estimated streams, the network inputs,
    and the global rank of every image the streams were cut from, shape ``(N,)``.
    """
    from gttnet.geometry.neighbours import pose_weighted_chain
    from gttnet.geometry.triangulation import pseudo_triangulate

    pt = pseudo_triangulate(obs.centers(), obs.rays(), obs.visible, obs.cam_id)
    view, rank = _streams_view(obs, pt.X_init, k=order_k)
    if partner_order:
        view, rank = _quieter_streams(obs, view, rank, pt.cost)
    seq = prepare_inputs(view, k=k, dtype=dtype, pseudo=pt)
    assert seq.chain is not None  # a partial view always has its chain
    chain = pose_weighted_chain(seq.chain.numpy(), pt.X_init)
    return view, replace(seq, chain=torch.as_tensor(chain, dtype=dtype)), rank
