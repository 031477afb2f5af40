"""What real rigs and real detectors add to a capture: cameras that follow the subject, and detector habits.

Each function is off at its default and draws nothing from the generator then, so recipes that do not ask
for it give bit-identical shards.

* :func:`pan_tilt_zoom_poses`: a broadcast-style camera that stays in place but pans and tilts after the
  subject (with an operator's lag and aiming error) and optionally zooms to keep the subject a given height
  in the image: one ``cam_from_world`` and one ``K`` per image.
* :func:`correlate_along_streams`: detection noise that is correlated in time along each camera's stream
  (a detector's error drifts from frame to frame instead of being independent).
* :func:`swap_left_right`: whole-image left/right confusions (a detector labels the left knee "right").
* :func:`missed_runs`: joints missed for runs of consecutive frames (occlusion, motion blur), instead of
  independently per image.
"""

from __future__ import annotations

import numpy as np

from gttdata.cameras import look_at

__all__ = ["correlate_along_streams", "missed_runs", "pan_tilt_zoom_poses", "swap_left_right"]


def _stream_rows(cam_id: np.ndarray, time_s: np.ndarray) -> list[np.ndarray]:
    """Row indices of each camera's images in time order."""
    return [
        np.flatnonzero(cam_id == v)[np.argsort(time_s[cam_id == v], kind="stable")] for v in np.unique(cam_id)
    ]


def pan_tilt_zoom_poses(
    cam_from_world: np.ndarray,
    K: np.ndarray,
    cam_id: np.ndarray,
    time_s: np.ndarray,
    points3d: np.ndarray,
    rng: np.random.Generator,
    *,
    lag_s: float,
    aim_deg: float,
    subject_px: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-image poses (and focal lengths) of cameras that follow the subject.

    Each camera keeps its centre and turns to look at where its operator believes the subject is: the
    subject's centre (mean of its joints) low-pass filtered along the camera's own stream with time
    constant ``lag_s`` (the operator lags behind), plus an aiming error of std ``aim_deg`` that drifts as a
    random walk. With ``subject_px > 0`` the focal length is set per image so that the subject's extent
    (the largest distance of a joint from its centre, doubled) spans ``subject_px`` pixels.

    Args:
        cam_from_world: Fixed world→camera transform of each image's camera, shape ``(N, 4, 4)``.
        K: Intrinsics of each image, pixels, shape ``(N, 3, 3)``.
        cam_id: Camera of each image, shape ``(N,)``.
        time_s: Capture time of each image, seconds, shape ``(N,)``.
        points3d: Joints in world, metres, shape ``(N, J, 3)`` (NaN allowed for absent joints).
        rng: Random generator (used only here).
        lag_s: Operator lag, seconds (0: perfect tracking).
        aim_deg: Std of the aiming error, degrees.
        subject_px: Subject height to zoom to, pixels; 0 keeps each camera's focal length.

    Returns:
        ``(cam_from_world (N, 4, 4), K (N, 3, 3))`` of each image.

    Example:
        >>> from gttdata import ring_rig
        >>> rig = ring_rig(2)
        >>> X = np.zeros((4, 3, 3)); X[:, :, 0] = np.linspace(0.0, 1.0, 4)[:, None]  # subject walks along x
        >>> cam = np.array([0, 1, 0, 1])
        >>> T, K = pan_tilt_zoom_poses(rig.cam_from_world[cam], rig.K[cam], cam, np.arange(4.0), X,
        ...     np.random.default_rng(0), lag_s=0.0, aim_deg=0.0, subject_px=0.0)
        >>> h = np.einsum("nab,nb->na", K, np.einsum("nab,nb->na", T[:, :3, :3], X[:, 0]) + T[:, :3, 3])
        >>> bool(np.allclose(h[:, :2] / h[:, 2:], K[:, :2, 2]))  # the subject stays at the image centre
        True
    """
    T = cam_from_world.copy()
    K = K.copy()
    centre_world = np.einsum("nba,nb->na", cam_from_world[:, :3, :3], -cam_from_world[:, :3, 3])
    subject = np.nanmean(points3d, axis=1)  # (N, 3)
    extent = 2.0 * np.nanmax(np.linalg.norm(points3d - subject[:, None], axis=-1), axis=1)
    for rows in _stream_rows(cam_id, time_s):
        aim = subject[rows].copy()
        if lag_s > 0:
            for k in range(1, rows.size):
                a = 1.0 - np.exp(-(time_s[rows[k]] - time_s[rows[k - 1]]) / lag_s)
                aim[k] = aim[k - 1] + a * (subject[rows[k]] - aim[k - 1])
        err = np.zeros((rows.size, 2))
        if aim_deg > 0:
            steps = rng.normal(0.0, np.deg2rad(aim_deg) / np.sqrt(max(rows.size, 1)), (rows.size, 2))
            err = np.cumsum(steps, axis=0)
        for k, n in enumerate(rows):
            eye = centre_world[n]
            T[n] = look_at(eye, aim[k])
            if aim_deg > 0:  # turn the optical axis by the aiming error (pan about camera y, tilt about x)
                cy, sy, cx, sx = np.cos(err[k, 0]), np.sin(err[k, 0]), np.cos(err[k, 1]), np.sin(err[k, 1])
                turn = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]) @ np.array(
                    [[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]
                )
                T[n, :3, :3] = turn @ T[n, :3, :3]
                T[n, :3, 3] = -T[n, :3, :3] @ eye
            if subject_px > 0 and np.isfinite(extent[n]) and extent[n] > 0:
                depth = float(np.linalg.norm(subject[n] - eye))
                f = subject_px * depth / extent[n]
                K[n, 0, 0] = K[n, 1, 1] = f
    return T, K


def correlate_along_streams(
    eps: np.ndarray, cam_id: np.ndarray, time_s: np.ndarray, *, corr_s: float
) -> np.ndarray:
    """Unit-variance noise made an AR(1) process along each camera's stream (correlation time ``corr_s``).

    The innovations are the given draws, so the marginal distribution (and the RNG use) is unchanged:
    ``e_k = rho e_{k-1} + sqrt(1 - rho^2) eps_k`` with ``rho = exp(-dt / corr_s)``.

    Args:
        eps: Independent standard-normal draws, shape ``(N, ...)``.
        cam_id: Camera of each image, shape ``(N,)``.
        time_s: Capture time of each image, seconds, shape ``(N,)``.
        corr_s: Correlation time, seconds (0: returns ``eps`` unchanged).

    Returns:
        Correlated unit-variance noise, shape of ``eps``.

    Example:
        >>> e = np.random.default_rng(0).standard_normal((2000, 1))
        >>> c = correlate_along_streams(e, np.zeros(2000, int), np.arange(2000) / 30.0, corr_s=0.5)
        >>> round(float(np.corrcoef(c[1:, 0], c[:-1, 0])[0, 1]), 1), round(float(c.std()), 1)
        (0.9, 1.0)
    """
    if corr_s <= 0:
        return eps
    out = eps.copy()
    for rows in _stream_rows(cam_id, time_s):
        for k in range(1, rows.size):
            rho = np.exp(-(time_s[rows[k]] - time_s[rows[k - 1]]) / corr_s)
            out[rows[k]] = rho * out[rows[k - 1]] + np.sqrt(1.0 - rho * rho) * eps[rows[k]]
    return out


def swap_left_right(
    keypoints_px: np.ndarray, mirror: tuple[int, ...], rng: np.random.Generator, *, rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """Swap every left/right joint pair of an image with probability ``rate`` (a detector's confusion).

    Args:
        keypoints_px: 2-D joints, pixels, shape ``(N, J, 2)``.
        mirror: Each joint's left/right counterpart (itself on the midline), length J.
        rng: Random generator (not used when ``rate`` is 0).
        rate: Probability per image.

    Returns:
        ``(keypoints (N, J, 2), swapped (N,) bool)``.

    Example:
        >>> kp = np.arange(12.0).reshape(2, 3, 2)
        >>> out, s = swap_left_right(kp, (1, 0, 2), np.random.default_rng(0), rate=1.0)
        >>> out[0, 0].tolist(), bool(s.all())
        ([2.0, 3.0], True)
    """
    n = keypoints_px.shape[0]
    if rate <= 0 or not mirror:
        return keypoints_px, np.zeros(n, bool)
    swapped = np.asarray(rng.random(n) < rate, dtype=bool)
    out = keypoints_px.copy()
    out[swapped] = keypoints_px[swapped][:, list(mirror)]
    return out, swapped


def missed_runs(
    cam_id: np.ndarray,
    time_s: np.ndarray,
    n_joints: int,
    rng: np.random.Generator,
    *,
    rate: float,
    mean_run: float,
) -> np.ndarray:
    """Kept mask where each joint is missed in runs along its camera's stream.

    A two-state chain per camera and joint: a seen joint is lost with probability ``rate / ((1 - rate)
    mean_run)`` per frame and found again with probability ``1 / mean_run``, so that a fraction ``rate`` of
    the joints is missed, in runs of ``mean_run`` frames on average.

    Args:
        cam_id: Camera of each image, shape ``(N,)``.
        time_s: Capture time of each image, seconds, shape ``(N,)``.
        n_joints: J.
        rng: Random generator.
        rate: Stationary fraction of missed joints, in ``[0, 1)``.
        mean_run: Mean run length, frames (> 1).

    Returns:
        Kept mask, shape ``(N, J)`` bool (False = missed).

    Example:
        >>> keep = missed_runs(np.zeros(20000, int), np.arange(20000.0), 2, np.random.default_rng(1),
        ...                    rate=0.2, mean_run=8.0)
        >>> round(float(1 - keep.mean()), 1)
        0.2
    """
    n = cam_id.shape[0]
    keep = np.ones((n, n_joints), bool)
    p_found = 1.0 / mean_run
    p_lost = min(1.0, rate * p_found / max(1.0 - rate, 1e-9))
    for rows in _stream_rows(cam_id, time_s):
        u = rng.random((rows.size, n_joints))
        state = u[0] >= rate  # start in the stationary distribution
        keep[rows[0]] = state
        for k in range(1, rows.size):
            state = np.where(state, u[k] >= p_lost, u[k] < p_found)
            keep[rows[k]] = state
    return keep
