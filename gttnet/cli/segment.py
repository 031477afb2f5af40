"""The ``gttnet segment`` command: split a capture of disjoint events by its affinity graph and order each."""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path

import click

from gttdata.errors import friendly_errors
from gttdata.threads import threads_option
from gttnet.cli._options import AFFINITY_METHODS, SPLIT_DEFAULT

__all__ = ["register", "segment_cmd", "load_capture"]

log = logging.getLogger(__name__)

#: The files ``segment`` writes into ``--out``.
OUT_FILES = ("labels.csv", "segmentation.json", "affinity.png")


def load_capture(path: str, *, sample: int, split: str, variant: str = "orig"):
    """The stored capture ``sample`` of a generate recipe (built in memory), a shard file or a dataset dir.

    Returns:
        A :class:`~gttdata.capture.sample.CaptureSample`.
    """
    p = Path(path)
    if p.suffix in (".yaml", ".yml"):
        from gttdata.generate_plan import build_sample
        from gttdata.recipe import load_recipe

        samples = build_sample(load_recipe(p), split, sample)
        return next((s for s in samples if s.variant == variant), samples[0])
    if p.is_dir():
        from gttdata.dataset import CaptureDataset

        return CaptureDataset(p, split=split, variant=variant).sample(sample)
    from gttdata._cli_common import check_shard_split
    from gttnet.io.shards import read_shard_sample

    check_shard_split(p, split)
    return read_shard_sample(p, sample=sample, variant=variant)


@click.command("segment")
@click.argument("input_path", metavar="INPUT", type=click.Path())
@click.option(
    "--method",
    type=click.Choice(AFFINITY_METHODS),
    default="dloe",
    show_default=True,
    help="Method giving the affinity between images.",
)
@click.option(
    "--sample",
    "-s",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Sample index in --split.",
)
@click.option(
    "--split", default=SPLIT_DEFAULT, show_default=True, help="Split of a recipe or dataset directory INPUT."
)
@click.option(
    "--sequencing",
    type=click.Choice(["none", "partial", "full"]),
    default="none",
    show_default=True,
    help="Sequencing the method may use (stream order links events under partial).",
)
@click.option("--n-events", type=click.IntRange(min=1), default=None, help="Known number of events.")
@click.option(
    "--model",
    "model_path",
    type=click.Path(exists=True, dir_okay=False),
    default=None,
    help="Trained model file for --method gttnet [default: the bundled model].",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False),
    default="runs/segment",
    show_default=True,
    help="Folder of labels.csv, segmentation.json and affinity.png; refused if it holds them, unless "
    "--overwrite.",
)
@click.option("--overwrite", is_flag=True, help="Replace the segmentation already in --out.")
@click.option(
    "--json", "as_json", is_flag=True, help="Print the report (segmentation.json) as one JSON line."
)
@threads_option
@friendly_errors
def segment_cmd(
    input_path, method, sample, split, sequencing, n_events, model_path, out_dir, overwrite, as_json
):
    """Segment the temporally disjoint events of INPUT and recover each event's image order.

    INPUT is a gttdata generate recipe (.yaml, built in memory, e.g. recipes/gttdata/events.yaml), a
    shard file (.h5) or a dataset directory. Writes labels.csv (per image: event label and order),
    segmentation.json (with the adjusted Rand index and per-event Kendall tau when the truth is known)
    and affinity.png.

    \b
    Examples:
      gttnet segment recipes/gttdata/events.yaml --sample 1 --out runs/segment
      gttnet segment recipes/gttdata/events.yaml --sample 0 --n-events 3 --out runs/segment_3events
    """
    import numpy as np

    from gttdata.capture.views import make_view
    from gttdata.fileio import atomic_write, check_output
    from gttnet.apps.segment import score_segmentation, segment_capture
    from gttnet.evaluate.plots import plot_affinity

    out = Path(out_dir)
    files = [out / name for name in OUT_FILES]
    check_output(
        out, exists=any(f.exists() for f in files), resume=False, overwrite=overwrite,
        what="a segmentation", resumable=False,
    )  # fmt: skip
    cap = load_capture(input_path, sample=sample, split=split)
    obs, gt = make_view(cap, sequencing)
    if model_path is not None and method != "gttnet":
        raise click.BadParameter("--model applies only to --method gttnet", param_hint="--model")
    options = {"model": model_path} if model_path else {}
    try:
        rec, seg = segment_capture(obs, method=method, n_events=n_events, **options)
    except ValueError as exc:
        raise click.ClickException(str(exc)) from exc
    out.mkdir(parents=True, exist_ok=True)
    truth = cap.meta.get("event_id")
    event = np.asarray(truth)[gt.perm] if truth is not None else None
    with atomic_write(out / "labels.csv", "w") as f:
        w = csv.writer(f)
        w.writerow(["image", "stored_index", "camera", "event", "order_in_event", "true_event"])
        for i in range(obs.n_images):
            true = "" if event is None else int(event[i])
            w.writerow([i, int(gt.perm[i]), int(obs.cam_id[i]), int(seg.labels[i]), int(seg.order[i]), true])
    report = {
        "input": str(input_path),
        "sample": sample,
        "method": method,
        "sequencing": sequencing,
        "n_images": obs.n_images,
        "n_events": seg.n_events,
        "how": seg.how,
        "seconds": round(rec.seconds, 4),
    }
    if event is not None:
        report.update(score_segmentation(seg, event, gt.global_order))
    with atomic_write(out / "segmentation.json", "w") as f:
        f.write(json.dumps(report, indent=2) + "\n")
    plot_affinity(
        rec.affinity, seg.labels, seg.order, out / "affinity.png", title=f"{method}: {seg.n_events} events"
    )
    if as_json:
        click.echo(json.dumps({**report, "out": str(out)}))
    else:
        click.echo(" ".join(f"{k}={v}" for k, v in report.items() if k != "input") + f" -> {out}")


def register(main: click.Group) -> None:
    """Attach ``segment`` to the ``gttnet`` command group."""
    main.add_command(segment_cmd)
