"""The reconstruct pipeline the CLI calls: solve one input, assess it, report it and write its outputs.

``gttnet reconstruct`` resolves its input (a recording through :mod:`gttnet.recording`, or a stored
capture through :mod:`gttnet.io`) and hands it to :func:`solve_and_write`; the summary it returns is what
``--json`` prints. Messages for the user go through an ``echo(line)`` callable (stderr in the CLI).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from typing import Any

__all__ = [
    "assess",
    "method_fields",
    "mpjpe_reconstructed",
    "report_capture",
    "report_recording",
    "solve_and_write",
    "time_warnings_held",
    "timing_fields",
]


def method_fields(rec, camera_names=None) -> dict:
    """The method fields of a reconstruction's report.

    ``method`` = the method that ran (``auto`` names its choice, ``requested_method`` keeps "auto"),
    ``nan_joints`` (indices of the joints left NaN: never observed, or too few rays for the method),
    ``refined`` (GTT-Net: whether a DLOE round followed the network) and,
    after clock recovery, ``clock_offsets_s`` ({camera: s}). Where joints are NaN, ``mpjpe_mm`` is over
    the others.
    """
    out: dict[str, Any] = {"method": rec.info.get("method_ran", rec.method)}
    if out["method"] != rec.method:
        out["requested_method"] = rec.method
    if rec.nan_joints.size:
        out["nan_joints"] = rec.nan_joints.tolist()
    if "refined" in rec.info:
        out["refined"] = bool(rec.info["refined"])
    if "clock_offsets_s" in rec.info:
        names = list(camera_names or [])
        out["clock_offsets_s"] = {
            (names[int(k)] if str(k).isdigit() and int(k) < len(names) else str(k)): round(float(v), 6)
            for k, v in rec.info["clock_offsets_s"].items()
        }
    return out


def mpjpe_reconstructed(rec, gt_points) -> float:
    """MPJPE (mm) over the joints the method reconstructed: the joints it left NaN are not scored."""
    import numpy as np

    from gttnet.evaluate.metrics import mpjpe_mm

    keep = np.setdiff1d(np.arange(rec.n_joints), rec.nan_joints)
    return mpjpe_mm(rec.points3d[:, keep], gt_points[:, keep]) if keep.size else float("nan")


def report_capture(loaded, rec) -> dict:
    """The summary of a reconstruction of a stored capture (a shard, .mat or .json), scored where it holds truth."""
    import numpy as np

    from gttnet.evaluate.metrics import kendall_tau

    out = {
        "method": rec.method,
        "sequencing": rec.sequencing,
        "n_images": rec.n_images,
        "n_joints": rec.n_joints,
        "seconds": round(float(rec.seconds), 4),
    }
    if "windows" in rec.info:
        out["windows"] = rec.info["windows"]
    out.update(method_fields(rec))
    gt = loaded.ground_truth
    if gt is not None:
        out["mpjpe_mm"] = round(mpjpe_reconstructed(rec, gt.points3d), 4)
        if rec.order is not None and np.all(gt.global_order >= 0):
            out["order_kendall_tau"] = round(kendall_tau(rec.order, gt.global_order), 4)
    return out


def report_recording(view, rec, gt_points) -> dict:
    """The summary of a reconstruction of a recording (cameras by name), scored against an export's truth."""
    obs = view.observations
    out = {
        "method": rec.method,
        "sequencing": rec.sequencing,
        "n_images": rec.n_images,
        "n_joints": rec.n_joints,
        "n_cameras": len(view.camera_names),
        "seconds": round(float(rec.seconds), 4),
        "observed_fraction": round(float(obs.visible.mean()), 4),
    }
    if "windows" in rec.info:
        out["windows"] = rec.info["windows"]
    out.update(method_fields(rec, view.camera_names))
    if gt_points is not None:
        out["mpjpe_mm"] = round(mpjpe_reconstructed(rec, gt_points), 4)
    return out


class _Held(logging.Handler):
    """Collect log messages (the clock code's warnings, printed later by camera name)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


@contextlib.contextmanager
def time_warnings_held() -> Iterator[list[str]]:
    """Hold back the clock code's warning log lines; yields the list they are collected in."""
    sync_log = logging.getLogger("gttnet.sync")
    held = _Held()
    sync_log.addHandler(held)
    try:
        yield held.lines
    finally:
        sync_log.removeHandler(held)


def timing_fields(rec, view, *, held: list[str]) -> tuple[list[str], dict]:
    """Clock recovery's timing warnings by camera name, and the summary's timing fields.

    Where the reconstruction's ``info`` has no timing checks (windows: one recovery per window), the held
    log lines are printed once each, cameras by index. The fields, where clocks were recovered:
    ``frame_rates_hz`` ({name: Hz}) and ``cameras_left_out`` ({name: reason}).
    """
    from gttnet.sync.rates import time_warnings

    names = dict(enumerate(view.camera_names))
    lines = time_warnings(rec.info, names) if "time_warnings" in rec.info else list(dict.fromkeys(held))
    out: dict = {}
    rates = (rec.info.get("frame_rates") or {}).get("cameras")
    if rates:
        out["frame_rates_hz"] = {names.get(int(c), c): round(r["used_hz"], 4) for c, r in rates.items()}
    if rec.info.get("cameras_left_out"):
        out["cameras_left_out"] = {
            names.get(int(c), c): why for c, why in rec.info["cameras_left_out"].items()
        }
    return lines, out


def assess(rec, obs, summary: dict):
    """``rec`` self-assessed (windowed runs assess the whole), with ``quality`` and ``auto`` in ``summary``.

    Multi-subject results (rows per subject) are left as they are.
    """
    from gttnet.methods import assessed

    if rec.n_images != obs.n_images:
        return rec
    rec = assessed(rec, obs)
    summary["quality"] = rec.info["quality"]
    if "auto" in rec.info:
        summary["auto"] = rec.info["auto"]
    return rec


def solve_and_write(
    inp: dict, run: dict, spec_m, out_paths: list[str], echo: Callable[[str], None], warning_handler=None
) -> dict:
    """Run the method on a resolved input, assess it, write its outputs and return the summary.

    Args:
        inp: The resolved input (``loaded``, ``view``, ``gt``, ``image_index``, ``source``,
            ``recording_json``, and for recordings ``skeleton`` and ``recording``).
        run: The run's settings: ``method``, ``options``, ``subjects`` (stacked skeletons of a stored
            capture, solved by ``multi_subject``, e.g. :func:`gttnet.apps.multi_subject.reconstruct_loaded_subjects`), ``window_arg``, ``resample_hz``, ``trc``, ``export_keypoints``, ``overwrite``, ``seed``,
            ``progress``, ``quiet`` and ``sequencing_given``.
        spec_m: The method's registry entry.
        out_paths: Output files (their suffix picks the format).
        echo: Prints one line for the user (stderr).
        warning_handler: A logging handler that shows the writers' warnings (None: none added).

    Raises:
        ValueError: The method or a writer refused the input (one line).
    """
    from gttnet.methods import check_sequencing, reconstruct
    from gttnet.recording import export_keypoints_on_clock, marker_names, timing_options, write_outputs

    method, options, quiet, progress = run["method"], run["options"], run["quiet"], run["progress"]
    loaded, view, obs = inp["loaded"], inp["view"], inp["view"].observations
    if not run["sequencing_given"] and not quiet:
        echo(
            f"sequencing: {obs.sequencing} (the richest the input supports; "
            "choose with --sequencing none|partial|full)"
        )
    check_sequencing(obs, spec_m)
    blind = int((~obs.visible.any(axis=1)).sum())
    if blind and obs.sequencing == "none" and not quiet:
        echo(
            f"warning: {blind} of {obs.n_images} images see no joint; without sequencing nothing places them, "
            "so their 3-D poses are placeholders (each camera's frame order, --sequencing partial, "
            "interpolates them)"
        )
    held: list[str] = []
    if run["subjects"] > 1:  # stacked skeletons of a stored capture: the application the CLI passes
        rec, summary = run["multi_subject"](
            loaded, method=method, n_subjects=run["subjects"], seed=run["seed"] or 0, **options
        )
    elif run["window_arg"] is not None:
        from gttnet.windowed import reconstruct_windowed

        with time_warnings_held() as held:
            rec = reconstruct_windowed(
                obs,
                method,
                window=run["window_arg"],
                progress=progress,
                **timing_options(method, view),
                **options,
            )
        summary = (
            report_capture(loaded, rec) if loaded is not None else report_recording(view, rec, inp["gt"])
        )
    else:
        with time_warnings_held() as held:
            rec = reconstruct(obs, method, **timing_options(method, view), **options)
        summary = (
            report_capture(loaded, rec) if loaded is not None else report_recording(view, rec, inp["gt"])
        )
    lines, fields = timing_fields(rec, view, held=held)
    if not quiet:
        for line in lines:
            echo(f"warning: {line}")
    summary.update(fields)
    if blind:
        summary["images_without_joints"] = blind
    rec = assess(rec, obs, summary)
    if out_paths:
        handler = warning_handler or logging.NullHandler()
        logging.getLogger("gttnet.recording").addHandler(handler)
        try:
            write_outputs(
                rec,
                view,
                out_paths,
                run["resample_hz"],
                image_index=inp["image_index"],
                source=inp["source"],
                recording_json=inp["recording_json"],
                trc=run["trc"] | {"names": marker_names(inp.get("skeleton"), obs)},
            )
        finally:
            logging.getLogger("gttnet.recording").removeHandler(handler)
    if run["export_keypoints"] is not None:
        export_keypoints_on_clock(
            inp.get("recording"),
            rec,
            view,
            run["export_keypoints"],
            rate_hz=run["resample_hz"],
            overwrite=run["overwrite"],
        )
    return summary
