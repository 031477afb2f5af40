"""Trained GTT-Net at inference: model files, the bundled model, and the ``"gttnet"`` reconstruction method."""

from __future__ import annotations

import functools
import logging
from pathlib import Path

import numpy as np
import torch

from gttdata.capture.views import Observations
from gttnet.errors import ModelError
from gttnet.geometry.candidates import use_candidate_search
from gttnet.geometry.ordering import (
    spectral_order,
    stream_consistent_order,
    timestamp_order,
)
from gttnet.methods import Reconstruction, register_method
from gttnet.model.files import MODEL_FORMAT, read_model_file, write_model_file
from gttnet.model.inputs import SequenceInput, pose_order, prepare_inputs, stream_ordered_view_and_inputs
from gttnet.model.network import GTTNet, GTTNetConfig

__all__ = [
    "BUNDLED_MODEL",
    "BUNDLED_NONE_MODEL",
    "BUNDLED_POINTNET_MODEL",
    "REFINE_DEFAULT",
    "REFINE_ROUNDS",
    "STREAM_ORDER_K",
    "bundled_model_for",
    "MODEL_FORMAT",
    "save_model",
    "load_model",
    "GTTNetReconstructor",
    "reconstruct_gttnet",
]

log = logging.getLogger(__name__)

#: The model shipped with the package (written by the lead after training ``recipes/gttnet/default.yaml``).
BUNDLED_MODEL = Path(__file__).resolve().parent.parent / "assets" / "gttnet_default.pt"
#: The CMU-31 model for captures without sequencing: the bundled model fine-tuned on order-free captures only
#: (``recipes/gttnet/default_none.yaml``; docs/MODEL_CARD.md). Optional: without it ``none`` uses BUNDLED_MODEL.
BUNDLED_NONE_MODEL = BUNDLED_MODEL.with_name("gttnet_default_none.pt")
#: The cross-domain (PointNet) model for any other skeleton (``recipes/gttnet/pointnet.yaml``); it may be
#: absent, when no trained model was good enough to ship (see docs/MODEL_CARD_POINTNET.md).
BUNDLED_POINTNET_MODEL = BUNDLED_MODEL.with_name("gttnet_pointnet.pt")
#: Links per image of the pose graph that orders each camera's images before the network runs on an
#: order-free capture (:func:`gttnet.model.inputs.prepare_stream_ordered_inputs`). Chosen on the validation
#: splits (bundled CMU-31 models, none, mean MPJPE mm for k = 16 / 32 / 64): paper protocol (16 captures)
#: 257.0 / 249.2 / 254.1, CMU (10) 229.8 / 226.2 / 225.9, the mixed default set (20) 304.4 / 301.7 / 310.1.
STREAM_ORDER_K = 32
#: DLOE rounds (W-, D- and X-step) of the refinement. One: on the validation captures below, one round was
#: both the most accurate and the cheapest (PointNet model, 24 human + 8 hand captures, sum of means for
#: 1 / 2 / all rounds: none 67.14 / 67.45 / 67.77 mm, partial 34.12 / 41.01 / 43.31 mm; 0.09 / 0.13 / 0.33 s
#: per capture); more rounds pull the structure back toward DLOE's own solution.
REFINE_ROUNDS = 1
#: Whether ``--method gttnet`` polishes the network's structure with a DLOE round by default, per
#: ``(PointNet variant, sequencing)``; pairs not listed do not. Chosen on each model's validation captures
#: by the rule that replaces models (sum of validation means at least 2 % lower), mean MPJPE mm, network
#: alone / refined: PointNet (24 human + 8 hand captures) none 67.62 + 4.07 / 63.27 + 3.87 (-6.3 %),
#: partial 50.89 + 3.56 / 30.69 + 3.43 (-37 %), full 13.71 + 3.12 / 11.84 + 3.00 (-12 %); CMU-31 models
#: (paper 16 + CMU 10 + default 20 captures) partial 686.5 / 609.6 (-11 %), none 726.1 / 721.0 (-0.7 %:
#: off), full 195.5 / 252.4 (worse on the captures that fail: off).
REFINE_DEFAULT: dict[tuple[bool, str], bool] = {
    (True, "none"): True,
    (True, "partial"): True,
    (True, "full"): True,
    (False, "partial"): True,
}


def bundled_model_for(skeleton, sequencing: str | None = None) -> Path:
    """The bundled model that fits a topology and sequencing condition.

    CMU-31 input gets the CMU-31 model, its order-free specialist (:data:`BUNDLED_NONE_MODEL`) under
    ``none`` sequencing when installed; any other skeleton gets the PointNet model.

    Args:
        skeleton: The input's :class:`gttdata.skeleton.Skeleton`.
        sequencing: ``"none"``, ``"partial"``, ``"full"`` or None (condition unknown: the general model).

    Raises:
        ModelError: The fitting model is not installed (the message says how to get or pass one).
    """
    from gttdata.skeleton import CMU31_JOINTS

    if skeleton.joint_names == CMU31_JOINTS:
        if sequencing == "none" and BUNDLED_NONE_MODEL.is_file():
            return BUNDLED_NONE_MODEL
        return BUNDLED_MODEL
    if not BUNDLED_POINTNET_MODEL.is_file():
        raise ModelError(
            f"no bundled model for skeleton {skeleton.name!r} ({skeleton.n_joints} joints): the bundled "
            f"{BUNDLED_MODEL.name} expects CMU-31 and no cross-domain model is installed "
            f"({BUNDLED_POINTNET_MODEL.name}); train one with 'gttnet train recipes/gttnet/pointnet.yaml' "
            "and pass --model RUN_DIR/model.pt"
        )
    return BUNDLED_POINTNET_MODEL


def save_model(path: str | Path, model: GTTNet, *, card: dict | None = None) -> Path:
    """Write a model file (weights + config) and its JSON model card, with the file's SHA-256, next to it.

    Args:
        path: Destination ``.pt`` file.
        model: Trained network.
        card: Model-card fields (recipe, data, metrics...), JSON-serialisable.

    Returns:
        The model path.

    Raises:
        OutputError: One line naming the path when the write fails.
    """
    return write_model_file(path, model, card=card)


def load_model(path: str | Path | None = None, *, device: str | torch.device = "cpu") -> GTTNet:
    """Load a model file, a training run's checkpoint, or (``path=None``) the bundled model.

    The file is checked first: a model file against the SHA-256 in its card, a checkpoint against its
    own header (see :mod:`gttnet.model.files`).

    Args:
        path: A file written by :func:`save_model`, a ``checkpoint.pt``, a run directory, or None.
        device: Where to put the model.

    Returns:
        The network in eval mode.

    Raises:
        ModelError: No such file, no bundled model, a checksum mismatch, or not a GTT-Net model.
    """
    if path is None:
        if not BUNDLED_MODEL.is_file():
            raise ModelError(
                f"no trained model is available: {BUNDLED_MODEL} is not installed; train one with "
                "'gttnet train recipes/gttnet/default.yaml' and pass --model RUN_DIR/model.pt"
            )
        path = BUNDLED_MODEL
    p = Path(path)
    if p.is_dir():
        p = p / "model.pt" if (p / "model.pt").is_file() else p / "checkpoint.pt"
    payload = read_model_file(p)
    cfg = {**payload["config"], "widths": tuple(payload["config"]["widths"])}
    try:
        model = GTTNet(GTTNetConfig(**cfg))
        model.load_state_dict(payload["state_dict"])
    except (TypeError, RuntimeError) as exc:
        raise ModelError(f"{p}: weights do not match the stored config ({str(exc).splitlines()[0]})") from exc
    return model.to(device).eval()


class GTTNetReconstructor:
    """Reconstruct with a trained GTT-Net from :class:`Observations` only (ground truth never enters).

    The loaded model is never modified: inference options are arguments of each call.

    Args:
        model_path: Model file or run directory; None uses the bundled model.
        device: ``"auto"`` (CUDA when available), ``"cpu"`` or ``"cuda"``.
        lambda2: Default ray weight of the DLOE layer for calls that pass none: a number, ``"auto"`` or
            None (the model's own; see :meth:`__call__`).
        candidates: Neighbour search under ``none`` sequencing (see
            :func:`gttnet.model.inputs.prepare_inputs`): ``"auto"``, ``"dense"`` or ``"kdtree"``.
        stream_order: Under ``none`` sequencing with the dense search, first order each camera's images by
            the pseudo-triangulated poses and reconstruct the capture as a ``partial`` one whose chain
            links are weighted by pose similarity
            (:func:`gttnet.model.inputs.prepare_stream_ordered_inputs`); False runs the network on the
            order-free input as it is. None (default): on for the single-topology GTT-Net; for the PointNet
            variant on when the DLOE round follows the network and off when it runs alone, as chosen on
            each model's validation captures (docs/MODEL_CARD.md, docs/MODEL_CARD_POINTNET.md). The k-d
            tree search (large captures) never orders streams.
    """

    def __init__(
        self,
        model_path: str | Path | None = None,
        *,
        device: str = "auto",
        lambda2: float | str | None = None,
        candidates: str = "auto",
        stream_order: bool | None = None,
    ) -> None:
        if device == "auto":
            device = "cuda" if torch.cuda.is_available() else "cpu"
        self.device = torch.device(device)
        self.candidates = candidates
        self.model = load_model(model_path, device=self.device)
        self.stream_order = None if stream_order is None else bool(stream_order)
        self.lambda2 = lambda2

    @torch.no_grad()
    def __call__(
        self,
        obs: Observations,
        *,
        top_q: int | None = None,
        lambda2: float | str | None = None,
        refine: bool | None = None,
    ) -> Reconstruction:
        """Reconstruct one capture.

        Args:
            obs: Observations of one sequencing condition.
            top_q: Affinities kept per image at test time (the sparsity ablation); None keeps the
                model's own Q.
            lambda2: Ray weight of the DLOE layer; None keeps the reconstructor's, else the model's own
                setting (rays pinned for the bundled model). A finite, noise-aware value
                (:func:`gttnet.solvers.xstep.noise_aware_lambda2`) lets joints leave their rays by about
                the pixel noise; the learned affinity is unchanged. ``"auto"`` measures the noise along
                the camera streams (:func:`gttnet.geometry.noise.auto_lambda2`: the given streams, or under
                ``none`` the estimated ones) and weights each image for its own depth; pinned where no
                stream is long enough. ``info["noise_px"]`` and ``info["lambda2"]`` (median) report it.
            refine: Run :data:`REFINE_ROUNDS` of DLOE's alternation
                (:func:`gttnet.baselines.dloe.reconstruct_dloe`) from the network's structure instead of
                from the pseudo-triangulation: the learned affinity picks the starting point, DLOE's W-, D-
                and X-steps polish it with the same ray weight. None: the default for the model and
                sequencing (:data:`REFINE_DEFAULT`). ``info["refined"]`` says whether it ran,
                ``info["refine_iterations"]`` how many rounds.

        Returns:
            :class:`Reconstruction` with points3d (N, J, 3) in world metres, the solver's (or, refined,
            DLOE's) affinity and the
            recovered order: the timestamp order under ``full``, never contradicting a stream under
            ``partial``, under ``none`` the spectral order of a nearest-neighbour graph over poses
            (:func:`gttnet.model.inputs.pose_order`): the refined poses after the DLOE round, else the
            pseudo-triangulated ones the streams were ordered by, else the reconstructed ones.
            ``info["stream_order"]`` says whether the streams were ordered first.
        """
        if not isinstance(obs, Observations):
            raise TypeError(f"GTTNetReconstructor takes Observations, got {type(obs).__name__}")
        if top_q is not None and int(top_q) < 1:
            raise ValueError(f"top_q must be >= 1, got {top_q}")
        lambda2 = self.lambda2 if lambda2 is None else lambda2
        if isinstance(lambda2, str) and lambda2 != "auto":
            raise ValueError(f"lambda2 must be a number, 'auto' or None, got {lambda2!r}")
        cfg = self.model.config
        if refine is None:
            refine = REFINE_DEFAULT.get((cfg.pointnet, obs.sequencing), False)
        stream_order = (not cfg.pointnet or refine) if self.stream_order is None else self.stream_order
        streams = (
            obs.sequencing == "none"
            and stream_order
            and not use_candidate_search("none", obs.n_images, self.candidates)
        )
        streams_view, pose_rank = obs, None
        if streams:
            streams_view, seq, pose_rank = stream_ordered_view_and_inputs(
                obs, k=cfg.k, order_k=STREAM_ORDER_K, partner_order=cfg.pointnet
            )
        else:
            seq = prepare_inputs(obs, k=cfg.k, candidates=self.candidates)
        noise_px = None
        ray_weight: float | np.ndarray | None = None if isinstance(lambda2, str) else lambda2
        if lambda2 == "auto":
            ray_weight, noise_px = _own_noise_lambda2(streams_view, seq)
        out = self.model([seq.to(self.device)], solve=True, top_q=top_q, lambda2=ray_weight, decode=False)[0]
        affinity = out.a_sparse.double().cpu().numpy()
        x_est = out.x_est.double().cpu().numpy()
        refine_iterations = None
        if refine:
            from gttnet.baselines.dloe import reconstruct_dloe

            ray_kw = {} if ray_weight is None else {"lambda2": ray_weight}
            polished = reconstruct_dloe(
                obs, candidates=self.candidates, x_start=x_est, max_iter=REFINE_ROUNDS, **ray_kw
            )
            x_est, affinity = polished.points3d, polished.affinity
            refine_iterations = polished.info["iterations"]
        if refine and obs.sequencing == "none":
            # The refined poses' own pose graph: with the DLOE round (PointNet model, streams ordered first,
            # its training families' validation captures) mean Kendall tau 0.877 / 0.943 (humans / hands)
            # against 0.777 / 0.831 for the order the streams were cut from.
            order = pose_order(x_est, k=16)
        elif pose_rank is not None:
            # The global order the streams were cut from (the pseudo-triangulated poses' pose graph), not
            # a second one over the network's poses: on the validation splits (16 captures each, bundled
            # models) mean Kendall tau paper 0.783 against 0.666, CMU 0.733 against 0.733, default 0.614
            # against 0.616, and 8 ms less at 300 images.
            order = pose_rank
        elif obs.sequencing == "none":
            # Ordered by the poses the network reconstructed, not by its affinity: on the paper protocol's
            # validation split (16 sequences, bundled model) Kendall tau 0.70 against 0.63 for the spectral
            # order of the learned neighbourhood affinity (k = 8: 0.65, k = 4: 0.39; k chosen there).
            order = pose_order(x_est, k=16)
        else:
            order = _given_order(obs, affinity)
        return Reconstruction(
            points3d=x_est,
            affinity=affinity,
            order=order,
            info={
                "k": cfg.k,
                "top_q": cfg.top_q if top_q is None else int(top_q),
                "device": str(self.device),
                "stream_order": streams,
                "lambda2": _summary(ray_weight),
                "noise_px": noise_px,
                "refined": bool(refine),
                "refine_iterations": refine_iterations,
            },
        )


def _summary(lambda2: float | np.ndarray | None) -> float | None:
    """The ray weight as ``info`` reports it (JSON): pinned None, else the number or the per-image median."""
    return None if lambda2 is None else float(np.median(lambda2))


def _own_noise_lambda2(obs: Observations, seq: SequenceInput) -> tuple[np.ndarray | None, float | None]:
    """``lambda2="auto"``: the ray weight for the noise measured along the capture's camera streams.

    The streams are the given ones (``partial``; ``full``: the stream index, else each camera's timestamp
    order) or, under ``none``, the ones the stream ordering estimated; without any (order-free input that
    was not stream-ordered) the rays stay pinned. Depth from the pseudo-triangulated ``x_init``.
    """
    from gttnet.geometry.noise import auto_lambda2
    from gttnet.geometry.ordering import stream_ranks

    streams = obs.stream_index
    if streams is None and obs.timestamp_s is not None:
        streams = stream_ranks(timestamp_order(obs.timestamp_s), obs.cam_id)
    if streams is None:
        return None, None
    return auto_lambda2(
        obs.keypoints_px,
        obs.visible,
        obs.cam_id,
        streams,
        obs.K,
        obs.cam_from_world,
        seq.x_init.double().numpy(),
    )


def _given_order(obs: Observations, affinity: np.ndarray) -> np.ndarray:
    """The order the sequencing condition fixes.

    The order the sequencing condition fixes: the timestamps under ``full``; under ``partial`` the
    affinity's spectral order made to agree with every stream.
    """
    if obs.sequencing == "full":
        assert obs.timestamp_s is not None  # a full view carries its timestamps
        return timestamp_order(obs.timestamp_s)
    assert obs.stream_index is not None  # a partial view carries its stream order
    return stream_consistent_order(spectral_order(affinity), obs.cam_id, obs.stream_index)


@functools.lru_cache(maxsize=8)
def cached_reconstructor(
    model: str | None = None,
    candidates: str = "auto",
    stream_order: bool | None = None,
    device: str = "auto",
) -> GTTNetReconstructor:
    """The one loaded-model cache: a :class:`GTTNetReconstructor` per model path (None = bundled) and options."""
    return GTTNetReconstructor(model, device=device, candidates=candidates, stream_order=stream_order)


@register_method("gttnet", requires="none", summary="GTT-Net: learned affinity + DLOE layer (trained model)")
def reconstruct_gttnet(
    obs: Observations,
    model: str | None = None,
    lambda2: float | str | None = None,
    top_q: int | None = None,
    candidates: str = "auto",
    stream_order: bool | None = None,
    refine: bool | None = None,
) -> Reconstruction:
    """GTT-Net with a bundled model or a given model file.

    The bundled model that fits the input's topology and sequencing (:func:`bundled_model_for`: for
    CMU-31 the order-free specialist under ``none`` and the general CMU-31 model otherwise, the PointNet
    model for other skeletons), or the model file/run directory ``model``. ``lambda2`` and
    ``top_q`` override the model's DLOE ray weight and test-time Q for this call (see
    :meth:`GTTNetReconstructor.__call__`); the cached model is not modified. ``candidates`` and
    ``stream_order`` as in :class:`GTTNetReconstructor`; ``refine`` as in :meth:`GTTNetReconstructor.__call__`.
    """
    if model is None:
        model = str(bundled_model_for(obs.skeleton, obs.sequencing))
    return cached_reconstructor(str(model), candidates, stream_order)(
        obs, top_q=top_q, lambda2=lambda2, refine=refine
    )
