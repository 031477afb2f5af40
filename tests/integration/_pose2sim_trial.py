"""A Pose2Sim-like session built from a simulated walk (test helper): Config.toml, calibration, pose folders."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gttdata import ring_rig
from gttdata.calibration import save_calibration
from gttdata.cameras import CameraRig
from gttdata.detectors import Keypoints2D
from gttdata.detectors.openpose import write_openpose
from gttdata.mocap.procedural import generate_motion
from gttdata.skeletons import derive_positions

#: HALPE-26 columns in BODY_25B order (COCO-17, neck, head top, left then right foot points).
HALPE26_TO_BODY25B = list(range(17)) + [18, 17, 20, 22, 24, 21, 23, 25]
FPS = 30.0
N_CAMERAS = 4


def body25b_walk(duration_s: float = 3.0) -> np.ndarray:
    """A walk on BODY_25B's points at 120 Hz, metres, world Z up, shape ``(T, 25, 3)``."""
    walk = generate_motion("walk", seed=3, duration_s=duration_s, fps_hz=120.0)
    return derive_positions(walk.positions, "halpe26")[:, HALPE26_TO_BODY25B]


def write_session(
    root: Path, *, drop: tuple[int, ...] = (0,) * N_CAMERAS, sigma_px: float = 1.0, seed: int = 0
) -> tuple[Path, CameraRig, np.ndarray]:
    """Write a session with one participant and one trial; camera ``v`` loses its first ``drop[v]`` frames.

    Camera ``v``'s frame ``k`` is taken at ``k / 30 + v / 120`` s (cameras a quarter frame apart); a
    camera started late (``drop``) numbers its frames from its own start. Every 17th frame of camera 2 is
    Pose2Sim's ``"people": [{}]``. Returns the trial folder, the rig and the true points of each camera's
    kept frames (a list per camera of ``(frames, 25, 3)``).
    """
    rng = np.random.default_rng(seed)
    X = body25b_walk()
    rig = ring_rig(N_CAMERAS, radius_m=4.0, rng=np.random.default_rng(1), jitter_m=0.1)
    rig = CameraRig(
        tuple(c.__class__(**{**c.__dict__, "name": f"cam_{v + 1:02d}"}) for v, c in enumerate(rig.cameras))
    )
    (root / "calibration").mkdir(parents=True)
    save_calibration(rig, root / "calibration" / "Calib_scene.toml")
    (root / "Config.toml").write_text('[project]\nframe_rate = 30\n\n[pose]\npose_model = "BODY_25B"\n')
    trial = root / "P01" / "T01"
    (trial / "pose").mkdir(parents=True)
    (root / "P01" / "Config.toml").write_text("[project]\nparticipant_height = 1.72\n")
    truth = []
    for v, cam in enumerate(rig.cameras):
        idx = np.arange(v, X.shape[0], 4)  # 120 Hz samples at k / 30 + v / 120
        pts = X[idx]
        px, depth = cam.project(pts)
        px = px + rng.normal(0, sigma_px, px.shape)
        ok = (depth > 0) & np.all((px >= 0) & (px < np.array(cam.image_size)), axis=-1)
        keep = np.arange(drop[v], idx.shape[0])
        score = np.where(ok, 0.9, np.nan)[keep]
        kp = Keypoints2D(
            xy=np.where(ok[..., None], px, np.nan)[keep],
            score=score,
            frame=keep - drop[v],
            joint_names=tuple(f"kp{j}" for j in range(25)),
        )
        folder = trial / "pose" / f"cam{v + 1:02d}_json"
        write_openpose(kp, folder, prefix=f"T01_cam{v + 1:02d}")
        if v == 2:
            for f in sorted(folder.glob("*.json"))[5::17]:
                f.write_text(json.dumps({"version": 1.3, "people": [{}]}))
        truth.append(pts[keep])
    return trial, rig, truth
