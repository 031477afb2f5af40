"""Pose2Sim and anipose folders as recordings: no project file, the tools' own layout.

**Pose2Sim** (a session, participant or trial folder)::

    Session/Config.toml                 # [project] frame_rate, [pose] pose_model, ...
    Session/calibration/Calib*.toml     # or a .qca.txt / .xcp / intri.yml the calibration step converts
    Session/P01/Config.toml             # optional: overrides the session's keys
    Session/P01/Trial1/Config.toml      # optional: overrides again
    Session/P01/Trial1/pose/cam01_json/*_keypoints.json   # or pose-associated/ or pose-sync/

The ``Config.toml`` files from the session down to the trial are merged, the deepest winning (Pose2Sim's
own rule). ``[project] frame_rate`` gives every camera's rate (``"auto"``: read from the trial's
``videos/``), ``[pose] pose_model`` the skeleton (``BODY_25B``, ``HALPE_26``... see
:data:`gttdata.skeletons_detectors.POSE2SIM_MODELS`). The keypoints are read from ``pose-associated/``
(one person already chosen per frame) when the trial has it, else ``pose-sync/``, else ``pose/``.

**anipose** (a session folder of a project)::

    project/config.toml                 # optional here; [triangulation] cam_regex
    project/session/calibration/calibration.toml
    project/session/pose-2d/trial-camA.h5     # DeepLabCut files, one per camera

Cameras are matched to keypoint folders by number: the last group of digits of the calibration's camera
name (``cam_01``, ``int_cam01_img``) and of the folder's (``cam01_json``) must agree. When no number
matches (names without digits, or anipose's letters), the cameras are matched by name through
``cam_regex``, else in natural order with a warning.
"""

from __future__ import annotations

import logging
import re
import tomllib
from pathlib import Path

from gttdata.calibration import load_calibration
from gttdata.errors import CalibrationError, KeypointFormatError
from gttdata.recording import CameraInput, RecordingSpec

__all__ = ["POSE_FOLDERS", "is_recording_folder", "spec_from_folder", "trial_folders"]

log = logging.getLogger(__name__)

#: Keypoint folders of a Pose2Sim trial, in the order they are preferred.
POSE_FOLDERS: tuple[str, ...] = ("pose-associated", "pose-sync", "pose")

_CALIB_SUFFIXES = (".toml", ".qca.txt", ".xcp", ".yml", ".yaml")
_VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v")


def _natural_key(name: str) -> list:
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def _number(name: str) -> int | None:
    m = re.search(r"(\d+)(?!.*\d)", name)
    return int(m.group(1)) if m else None


def _is_trial(path: Path) -> bool:
    return any((path / p).is_dir() for p in POSE_FOLDERS)


def _is_anipose(path: Path) -> bool:
    return (path / "pose-2d").is_dir()


def is_recording_folder(path: str | Path) -> bool:
    """Whether ``path`` is a Pose2Sim session/participant/trial folder or an anipose session folder."""
    path = Path(path)
    if not path.is_dir():
        return False
    if _is_trial(path) or _is_anipose(path):
        return True
    return bool(_trials(path))


def _trials(path: Path, depth: int = 2) -> list[Path]:
    """Trial folders at or below ``path`` (at most ``depth`` levels down)."""
    if _is_trial(path):
        return [path]
    if depth == 0:
        return []
    out: list[Path] = []
    for sub in sorted((p for p in path.iterdir() if p.is_dir()), key=lambda p: _natural_key(p.name)):
        if "calib" not in sub.name.lower():
            out += _trials(sub, depth - 1)
    return out


def trial_folders(path: str | Path) -> list[Path]:
    """Pose2Sim trial folders at or below ``path`` (two levels at most: session, participant), in natural order.

    A folder whose name holds ``calib`` is never searched (it is the calibration's).
    """
    path = Path(path)
    return _trials(path) if path.is_dir() else []


def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise KeypointFormatError(f"{path}: cannot parse: {exc}") from exc


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _config_chain(trial: Path, name: str = "Config.toml") -> tuple[dict, list[Path]]:
    """The merged configuration of ``trial`` (deepest wins) and the folders searched, top one first.

    The trial, its participant and its session folder are searched (Pose2Sim's three levels; a level
    without a ``Config.toml`` is skipped).
    """
    folders = [trial, trial.parent, trial.parent.parent][::-1]
    cfg: dict = {}
    for f in folders:
        if (f / name).is_file():
            cfg = _merge(cfg, _read_toml(f / name))
    return cfg, folders


def _calibration_file(folders: list[Path]) -> Path:
    """The calibration of a trial: a ``*calib*`` folder in the trial or a folder above, its file."""
    for f in reversed(folders):
        dirs = sorted(d for d in f.iterdir() if d.is_dir() and "calib" in d.name.lower())
        for d in dirs:
            files = sorted(p for p in d.iterdir() if p.is_file() and p.name.lower().endswith(_CALIB_SUFFIXES))
            tomls = [p for p in files if p.suffix.lower() == ".toml" and p.name.lower() != "config.toml"]
            tomls.sort(key=lambda p: not p.name.lower().startswith("calib"))  # Pose2Sim's Calib*.toml first
            pick = tomls or [p for p in files if not p.name.startswith("extri")]
            if pick:
                return pick[0]
    raise CalibrationError(
        f"{folders[-1]}: no calibration found: expected a calibration/ folder (in the trial or a folder above) "
        "holding a .toml, .qca.txt, .xcp or intri.yml"
    )


def _video_rate(folder: Path, number: int | None) -> float | None:
    """Frame rate of the camera's video in ``folder`` (OpenCV's reading of the container), or None."""
    import cv2

    if not folder.is_dir():
        return None
    vids = sorted(p for p in folder.iterdir() if p.suffix.lower() in _VIDEO_SUFFIXES)
    vids = [p for p in vids if number is None or _number(p.stem) == number] or []
    if not vids:
        return None
    cap = cv2.VideoCapture(str(vids[0]))
    try:
        rate = float(cap.get(cv2.CAP_PROP_FPS))
    finally:
        cap.release()
    return rate if rate > 0 else None


def _match(
    cal_names: list[str], sources: list[Path], regex: str | None, where: Path
) -> list[tuple[str, Path]]:
    """Pair calibration cameras with keypoint sources: by number, else by ``regex``, else natural order."""
    by_num = {_number(n): n for n in cal_names}
    nums = [_number(s.stem if s.is_file() else s.name) for s in sources]
    if None not in by_num and len(by_num) == len(cal_names) and all(n in by_num for n in nums):
        return [(by_num[n], s) for n, s in zip(nums, sources, strict=True)]
    if regex:
        pairs = []
        for s in sources:
            m = re.search(regex, s.stem if s.is_file() else s.name)
            name = m.group(1) if m and m.groups() else (m.group(0) if m else None)
            if name not in cal_names:
                break
            pairs.append((str(name), s))
        else:
            return pairs
    if len(cal_names) != len(sources):
        raise CalibrationError(
            f"{where}: cannot match keypoint sources {[s.name for s in sources]} to calibration cameras "
            f"{cal_names} by number, and their counts differ ({len(sources)} vs {len(cal_names)})"
        )
    log.warning(
        "%s: keypoint sources %s matched to calibration cameras %s in natural order (no numbers agree)",
        where,
        [s.name for s in sources],
        cal_names,
    )
    return list(zip(sorted(cal_names, key=_natural_key), sources, strict=True))


def _rate_value(value: object, where: str) -> float | None:
    if value is None or (isinstance(value, str) and value.strip().lower() == "auto"):
        return None
    if isinstance(value, int | float) and not isinstance(value, bool) and value > 0:
        return float(value)
    raise KeypointFormatError(f"{where}: frame_rate must be a positive number or 'auto', found {value!r}")


def _pose2sim_spec(path: Path) -> RecordingSpec:
    trials = _trials(path)
    if len(trials) != 1:
        found = ", ".join(str(t.relative_to(path)) for t in trials) or "none"
        raise KeypointFormatError(
            f"{path}: a recording folder needs exactly one trial (a folder with pose/ or pose-associated/), "
            f"found {len(trials)}: {found}; pass the trial folder"
        )
    trial = trials[0]
    cfg, folders = _config_chain(trial)
    pose = next(trial / p for p in POSE_FOLDERS if (trial / p).is_dir())
    sources = sorted((p for p in pose.iterdir() if p.is_dir()), key=lambda p: _natural_key(p.name))
    if not sources:
        raise KeypointFormatError(f"{pose}: no camera folders (cam01_json, ...) in it")
    rate = _rate_value((cfg.get("project") or {}).get("frame_rate"), f"{trial}/Config.toml [project]")
    model = (cfg.get("pose") or {}).get("pose_model")
    skeleton = None
    if model is not None:
        from gttdata.skeletons_detectors import pose2sim_model

        try:
            skeleton = pose2sim_model(str(model))
        except KeyError as exc:
            raise KeypointFormatError(f"{trial}: Config.toml [pose] pose_model: {exc.args[0]}") from None
    calib = _calibration_file(folders)
    rig, _ = load_calibration(calib, warn=False)
    pairs = _match([c.name for c in rig.cameras], sources, None, pose)
    cams = []
    for name, src in pairs:
        fps = rate if rate is not None else _video_rate(trial / "videos", _number(src.name))
        cams.append(CameraInput(name=name, keypoints=src, fps=fps))
    conf = (cfg.get("triangulation") or {}).get("likelihood_threshold_triangulation")
    return RecordingSpec(
        calibration=calib,
        cameras=tuple(cams),
        skeleton=skeleton,
        min_confidence=float(conf) if isinstance(conf, int | float) and 0 <= conf <= 1 else 0.1,
    )


def _anipose_spec(path: Path) -> RecordingSpec:
    cfg, folders = _config_chain(path, "config.toml")
    files = sorted(
        (p for p in (path / "pose-2d").iterdir() if p.suffix.lower() in (".h5", ".csv", ".slp")),
        key=lambda p: _natural_key(p.name),
    )
    if not files:
        raise KeypointFormatError(f"{path / 'pose-2d'}: no DeepLabCut .h5/.csv or SLEAP .slp files")
    regex = (cfg.get("triangulation") or {}).get("cam_regex")
    if regex:
        trials = sorted({re.sub(regex, "", p.stem) for p in files})
        if len(trials) > 1:
            raise KeypointFormatError(
                f"{path / 'pose-2d'}: {len(trials)} trials ({', '.join(trials)}); one recording is one trial "
                "(move the others aside)"
            )
    calib = _calibration_file(folders)
    rig, _ = load_calibration(calib, warn=False)
    pairs = _match([c.name for c in rig.cameras], files, regex, path / "pose-2d")
    cams = tuple(
        CameraInput(name=n, keypoints=f, fps=_video_rate(path / "videos-raw", _number(f.stem)))
        for n, f in pairs
    )
    return RecordingSpec(calibration=calib, cameras=cams)


def spec_from_folder(path: str | Path) -> RecordingSpec:
    """The recording of a Pose2Sim session/participant/trial folder or an anipose session folder.

    Frame rates come from the configuration (Pose2Sim's ``frame_rate``) or the videos; a camera whose rate
    is unknown has ``fps = None`` (``--fps`` supplies it).

    Raises:
        KeypointFormatError: Not one trial, no keypoint folders, or a malformed ``Config.toml`` field.
        CalibrationError: No calibration, or cameras that cannot be matched to keypoint folders.
    """
    path = Path(path)
    if not path.is_dir():
        raise KeypointFormatError(f"{path}: a recording folder must be a directory")
    if _is_anipose(path):
        return _anipose_spec(path)
    return _pose2sim_spec(path)
