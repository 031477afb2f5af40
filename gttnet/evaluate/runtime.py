"""Runtime study: seconds per sequence of GTT-Net and DLOE against the number of images (paper Fig. 5a)."""

from __future__ import annotations

import csv
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gttdata.capture.views import make_view
from gttnet.errors import ModelError
from gttnet.evaluate.recipe import RuntimeSpec

__all__ = ["RuntimeResult", "gttnet_timer", "run_runtime"]

log = logging.getLogger(__name__)


@dataclass
class RuntimeResult:
    """Timings of a runtime study.

    Args:
        lengths: Requested images per sequence.
        n_images: Images actually built per length.
        seconds: Method -> median seconds per sequence (over sequences and repeats), per length.
        spread: Method -> ``(min, max)`` seconds per length, over the same runs.
        notes: How each method was timed (e.g. an untrained network when no model is installed).
        markdown: The speed-up table.
    """

    lengths: list[int]
    n_images: list[int]
    seconds: dict[str, list[float]]
    notes: dict[str, str] = field(default_factory=dict)
    spread: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    markdown: str = ""


def gttnet_timer(model: str | None = None, device: str = "cpu"):
    """A callable ``obs -> points3d`` timing GTT-Net inference, and a note on which network it runs.

    Times what ``--method gttnet`` runs: :class:`~gttnet.model.inference.GTTNetReconstructor` with the
    trained model (the bundled one that fits the capture when ``model`` is None), order recovery and,
    under ``none``, the per-camera stream order included. Without a loadable model an untrained
    ``gttnet_base`` (:func:`gttnet.model.network.build_model`) runs the network and its DLOE layer only;
    inference time does not depend on the weights' values, but that path skips the order steps.

    Returns:
        ``(fn, note)``.
    """
    import torch

    from gttnet.model.inference import bundled_model_for, cached_reconstructor
    from gttnet.model.inputs import prepare_inputs

    try:
        from gttnet.model.inference import load_model

        load_model(model, device=device)  # fail early when there is no trained model
    except ModelError as exc:
        from gttnet.model.network import build_model

        net = build_model("gttnet_base").eval().to(device)

        @torch.no_grad()
        def run_untrained(obs) -> np.ndarray:
            seq = prepare_inputs(obs, k=net.config.k).to(device)
            return net([seq], solve=True, decode=False)[0].x_est.cpu().numpy()  # .cpu() waits for the device

        return run_untrained, f"untrained gttnet_base ({exc}); timing does not depend on the weights"

    def run(obs) -> np.ndarray:
        path = model if model is not None else str(bundled_model_for(obs.skeleton, obs.sequencing))
        return cached_reconstructor(path, device=device)(obs).points3d  # numpy: back on the host

    return (
        run,
        f"trained model {model or 'bundled (by skeleton and sequencing)'} on {device}, as --method gttnet runs it",
    )


def _samples_of_length(spec: RuntimeSpec, length: int, rate: float | None):
    from gttdata.generate_plan import build_sample
    from gttdata.recipe import load_recipe

    if rate is None:
        probe = build_sample(load_recipe(spec.generate, ["capture.window_s=1.0"]), spec.split, 0)[0]
        rate = probe.n_images / 1.0
    window = length / rate
    recipe = load_recipe(spec.generate, [f"capture.window_s={window:.6f}"])
    return [build_sample(recipe, spec.split, i)[0] for i in range(max(spec.sequences, 1))], rate


def _speedup_markdown(res: RuntimeResult) -> str:
    names = list(res.seconds)
    head = "| images | " + " | ".join(f"{m} [s], median (min..max)" for m in names) + " |"
    ratio = "dloe" in res.seconds and "gttnet" in res.seconds
    lines = [
        head + (" speed-up (DLOE / GTT-Net) |" if ratio else ""),
        "|---|" + "---|" * (len(names) + ratio),
    ]
    for i, n in enumerate(res.n_images):
        cells = []
        for m in names:
            lo, hi = res.spread[m][i] if m in res.spread else (res.seconds[m][i],) * 2
            cells.append(f"{res.seconds[m][i]:.3f} ({lo:.3f}..{hi:.3f})")
        if ratio:
            cells.append(f"{res.seconds['dloe'][i] / res.seconds['gttnet'][i]:.1f}x")
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    if ratio:
        mean = np.mean(np.array(res.seconds["dloe"]) / np.array(res.seconds["gttnet"]))
        lines += [
            "",
            f"Mean speed-up (ratio of medians): {mean:.1f}x (paper: ~30x against the open-source DLOE).",
        ]
    lines += ["", *[f"- {m}: {note}" for m, note in res.notes.items()]]
    return "\n".join(lines) + "\n"


def run_runtime(spec: RuntimeSpec, out_dir: str | Path, *, progress: bool = False) -> RuntimeResult:
    """Time each method per length; write ``runtime.csv``, ``runtime.md``, ``runtime.png``.

    Sequences are the first ``spec.sequences`` samples of ``spec.split`` of ``spec.generate`` with
    ``capture.window_s`` set so that each capture holds about ``length`` images; every sequence is timed
    ``spec.repeats`` times and the median over all those runs is reported, with their min..max.

    Args:
        spec: :class:`~gttnet.evaluate.recipe.RuntimeSpec`.
        out_dir: Output directory.
        progress: Log each timing at INFO.

    Returns:
        The :class:`RuntimeResult`.
    """
    import torch

    from gttnet.evaluate.plots import plot_runtime
    from gttnet.methods import reconstruct

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    runners, notes = {}, {}
    for m in spec.methods:
        if m == "gttnet":
            runners[m], notes[m] = gttnet_timer(spec.model, spec.device)
        else:
            runners[m] = lambda obs, m=m: reconstruct(obs, m).points3d
            notes[m] = f"gttnet.baselines.reconstruct(obs, {m!r})"
    notes["threads"] = f"torch threads {torch.get_num_threads()}, sequencing {spec.sequencing}"
    notes["runs"] = f"{max(spec.sequences, 1)} sequences x {spec.repeats} repeats per length"
    res = RuntimeResult(list(spec.lengths), [], {m: [] for m in spec.methods}, notes)
    res.spread = {m: [] for m in spec.methods}
    rate = None
    for length in spec.lengths:
        samples, rate = _samples_of_length(spec, length, rate)
        views = [make_view(sample, spec.sequencing)[0] for sample in samples]
        res.n_images.append(int(np.median([obs.n_images for obs in views])))
        if length == spec.lengths[0]:
            for fn in runners.values():
                fn(views[0])  # warm-up: imports, caches, first-call allocation
        # The methods take turns on each capture, so a slow spell of a shared machine hits all of them
        # alike instead of one method's whole block.
        times: dict[str, list[float]] = {m: [] for m in runners}
        for obs in views:
            for _ in range(spec.repeats):
                for m, fn in runners.items():
                    t0 = time.perf_counter()
                    fn(obs)
                    times[m].append(time.perf_counter() - t0)
        for m, runs in times.items():
            med = float(np.median(runs))
            res.seconds[m].append(med)
            res.spread[m].append((float(min(runs)), float(max(runs))))
            (log.info if progress else log.debug)("runtime %s N=%d: median %.3f s", m, res.n_images[-1], med)
    res.markdown = _speedup_markdown(res)
    with (out / "runtime.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["n_images", *spec.methods])
        for i, n in enumerate(res.n_images):
            w.writerow([n, *(f"{res.seconds[m][i]:.4f}" for m in spec.methods)])
    (out / "runtime.md").write_text("# Runtime: seconds per sequence\n\n" + res.markdown)
    plot_runtime(res.n_images, res.seconds, out / "runtime.png")
    return res
