"""Clock recovery (gttnet.sync): offsets of seconds, unequal rates, drift, dropped frames, invariances."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from gttdata.cameras import ring_rig
from gttdata.capture.sample import CaptureSample, temporal_affinity
from gttdata.capture.views import Observations, make_view
from gttnet.errors import GttNetError, SequencingError
from gttnet.sync import Clocks, apply_clocks, clock_times, recover_clocks
from tests.fixtures.scenes import body_positions


def _capture(
    offsets_s=(0.0, 1.3, 0.4),
    fps=(25.0, 30.0, 60.0),
    *,
    end_s: float = 3.0,
    drift_ppm=None,
    sigma_px: float = 1.0,
    n_joints: int = 12,
    seed: int = 0,
) -> CaptureSample:
    """Cameras started at ``offsets_s`` (s) at rates ``fps``, recording until ``end_s``; exact geometry."""
    v = len(fps)
    rig = ring_rig(v)
    drift = np.zeros(v) if drift_ppm is None else np.asarray(drift_ppm, dtype=np.float64)
    cams, times, idx = [], [], []
    for c in range(v):
        k = np.arange(int((end_s - offsets_s[c]) * fps[c]))
        cams.append(np.full(k.size, c))
        times.append(offsets_s[c] + k * (1.0 + 1e-6 * drift[c]) / fps[c])
        idx.append(k)
    t, cam, si = np.concatenate(times), np.concatenate(cams), np.concatenate(idx)
    o = np.argsort(t, kind="stable")
    t, cam, si = t[o], cam[o].astype(np.int32), si[o].astype(np.int32)
    n = t.size
    X = body_positions(t, n_joints, seed=seed)
    px, depth = np.empty((n, n_joints, 2)), np.empty((n, n_joints))
    for i in range(n):
        px[i], depth[i] = rig[cam[i]].project(X[i])
    vis = depth > 0
    noisy = px + np.random.default_rng(seed).normal(0.0, sigma_px, px.shape)
    nbr, w = temporal_affinity(t, cam, X)
    from gttdata.skeleton import Skeleton

    return CaptureSample(
        name=f"sync/{seed}",
        motion_name="synthetic_body",
        skeleton=Skeleton(
            name="toy",
            joint_names=tuple(f"j{i}" for i in range(n_joints)),
            parents=(-1,) + (0,) * (n_joints - 1),
        ),
        cam_id=cam,
        timestamp_s=t,
        stream_index=si,
        global_order=np.arange(n, dtype=np.int32),
        keypoints_px=np.where(vis[..., None], noisy, np.nan).astype(np.float32),
        visible=vis,
        keypoints_gt_px=px.astype(np.float32),
        K=np.stack([rig[c].K for c in cam]),
        cam_from_world=np.stack([rig[c].cam_from_world for c in cam]),
        image_size=np.array([rig[c].image_size for c in range(v)], dtype=np.int32),
        points3d=X,
        affinity_nbr=nbr,
        affinity_w=w,
    )


def _frame_errors(obs: Observations, gt_t: np.ndarray, clocks: Clocks, frame_times_s=None) -> np.ndarray:
    """Per-camera error of the recovered times, in frames, after removing the unobservable common shift."""
    err = clock_times(obs, clocks, frame_times_s=frame_times_s) - gt_t
    err -= np.median(err)
    return np.array(
        [np.median(err[obs.cam_id == c]) * clocks.rate_hz[k] for k, c in enumerate(clocks.cameras)]
    )


@pytest.fixture(scope="module")
def capture():
    return _capture()


@pytest.fixture(scope="module")
def recovered(capture):
    obs, gt = make_view(capture, "partial")
    return obs, gt, recover_clocks(obs, fps={0: 25.0, 1: 30.0, 2: 60.0})


def test_offsets_of_seconds_at_unequal_rates(recovered):
    obs, gt, clocks = recovered
    err = _frame_errors(obs, gt.timestamp_s, clocks)
    assert np.abs(err).max() < 0.1, err
    # Time 0 is the earliest camera's first frame: camera 0 here; the others started 1.3 s and 0.4 s later.
    np.testing.assert_allclose(clocks.offset_s, [0.0, 1.3, 0.4], atol=0.1 / 60)
    assert np.all(np.isfinite(clocks.offset_std_s)) and np.all(clocks.offset_std_s > 0)


def test_wrong_rates_are_worse(capture, recovered):
    obs, gt, clocks = recovered
    wrong = recover_clocks(obs, fps=30.0, check_rates=False)  # every camera taken at 30 Hz, unchecked
    good = np.abs(
        clock_times(obs, clocks) - gt.timestamp_s - np.median(clock_times(obs, clocks) - gt.timestamp_s)
    )
    bad_t = clock_times(obs, wrong)
    bad = np.abs(bad_t - gt.timestamp_s - np.median(bad_t - gt.timestamp_s))
    assert np.median(bad) > 10 * np.median(good)


def test_camera_relabelling_and_image_permutation(capture, recovered):
    obs, gt, clocks = recovered
    t_ref = clock_times(obs, clocks)
    relabel = np.array([7, 2, 5])  # camera 0 -> 7, 1 -> 2, 2 -> 5: new index order differs from the old
    perm = np.random.default_rng(3).permutation(obs.n_images)
    shuffled = replace(
        obs,
        cam_id=relabel[obs.cam_id][perm],
        K=obs.K[perm],
        cam_from_world=obs.cam_from_world[perm],
        keypoints_px=obs.keypoints_px[perm],
        visible=obs.visible[perm],
        stream_index=obs.stream_index[perm],
        image_size=obs.image_size,
    )
    c2 = recover_clocks(shuffled, fps={7: 25.0, 2: 30.0, 5: 60.0})
    assert c2.cameras.tolist() == [2, 5, 7]
    # The same answer up to the optimiser's tolerance (a hundredth of a 60 Hz frame).
    np.testing.assert_allclose(clock_times(shuffled, c2), t_ref[perm], atol=0.01 / 60)


def test_ground_truth_never_reaches_the_estimator(capture, recovered):
    obs, _, clocks = recovered
    rng = np.random.default_rng(0)
    corrupt = replace(
        capture,
        timestamp_s=np.sort(rng.uniform(0, 100, capture.n_images)),
        points3d=rng.normal(size=capture.points3d.shape),
        keypoints_gt_px=rng.normal(size=capture.keypoints_gt_px.shape).astype(np.float32),
        affinity_nbr=np.full_like(capture.affinity_nbr, -1),
    )
    obs2, _ = make_view(corrupt, "partial")
    c2 = recover_clocks(obs2, fps={0: 25.0, 1: 30.0, 2: 60.0})
    np.testing.assert_array_equal(c2.offset_s, clocks.offset_s)
    # A full view's timestamps are ignored too: garbage timestamps, same clocks.
    full, _ = make_view(capture, "full")
    full = replace(full, timestamp_s=rng.uniform(0, 1, full.n_images))
    c3 = recover_clocks(full, fps={0: 25.0, 1: 30.0, 2: 60.0})
    np.testing.assert_allclose(clock_times(full, c3), clock_times(full, clocks), atol=0.01 / 60)


def test_dropped_frames_need_frame_times(capture):
    obs, gt = make_view(capture, "partial")
    rates = np.array([25.0, 30.0, 60.0])
    tau = obs.stream_index / rates[obs.cam_id]
    # Drop 8 % of the frames; the video index is renumbered, the camera's own timestamps keep the gaps.
    keep = np.random.default_rng(1).random(obs.n_images) > 0.08
    renum = np.zeros(keep.sum(), dtype=np.int64)
    cam = obs.cam_id[keep]
    for c in range(3):
        renum[cam == c] = np.arange((cam == c).sum())
    dropped = replace(
        obs,
        cam_id=cam,
        K=obs.K[keep],
        cam_from_world=obs.cam_from_world[keep],
        keypoints_px=obs.keypoints_px[keep],
        visible=obs.visible[keep],
        stream_index=renum,
    )
    fps = {0: 25.0, 1: 30.0, 2: 60.0}
    with_times = recover_clocks(dropped, fps=fps, frame_times_s=tau[keep])
    t_ok = clock_times(dropped, with_times, frame_times_s=tau[keep]) - gt.timestamp_s[keep]
    assert np.abs(t_ok - np.median(t_ok)).max() * 60 < 0.2
    # Without them the renumbered streams cannot all fit one clock.
    blind = recover_clocks(dropped, fps=fps)
    t_bad = clock_times(dropped, blind) - gt.timestamp_s[keep]
    assert np.abs(t_bad - np.median(t_bad)).max() > 5 * np.abs(t_ok - np.median(t_ok)).max()


def test_drift_is_recovered_when_asked():
    cap = _capture(
        (0.0, 0.2, 0.5), (30.0, 30.0, 30.0), end_s=4.0, drift_ppm=(0.0, 3000.0, -3000.0), sigma_px=0.5
    )
    obs, gt = make_view(cap, "partial")
    clocks = recover_clocks(obs, fps=30.0, estimate_drift=True)
    rel = clocks.drift_ppm - clocks.drift_ppm[0]
    np.testing.assert_allclose(rel, [0.0, 3000.0, -3000.0], atol=800.0)  # 4 s: 3000 ppm is 0.36 frame
    assert np.abs(_frame_errors(obs, gt.timestamp_s, clocks)).max() < 0.1


def test_piecewise_recovery_follows_drift_over_the_whole_recording(monkeypatch):
    """A long recording is searched only in its first segment, yet the drift over all of it is recovered.

    The module constants are shrunk so a 40 s toy capture at 10 Hz stands for a long one: the full search
    sees the first 6 s only, where +-2000 ppm is 0.12 frame; by the end it is 0.8 frame.
    """
    import gttnet.sync.recover as rec

    monkeypatch.setattr(rec, "SEGMENT_S", 6.0)
    monkeypatch.setattr(rec, "WINDOW_S", 3.0)
    monkeypatch.setattr(rec, "N_WINDOWS", 5)
    cap = _capture(
        (0.0, 0.7, 0.3), (10.0, 10.0, 10.0), end_s=40.0, drift_ppm=(0.0, 2000.0, -2000.0), sigma_px=0.5,
        seed=4,
    )  # fmt: skip
    obs, gt = make_view(cap, "partial")
    clocks = recover_clocks(obs, fps=10.0, estimate_drift=True, piecewise=True)
    info = clocks.info["piecewise"]
    assert info["windows"] == 5
    # Bounded work: the segment plus the windows (with their search margins), not every image.
    assert info["segment_images"] + info["window_images"] < 0.75 * obs.n_images
    rel = clocks.drift_ppm - clocks.drift_ppm[0]
    np.testing.assert_allclose(rel, [0.0, 2000.0, -2000.0], atol=150.0)
    assert np.abs(_frame_errors(obs, gt.timestamp_s, clocks)).max() < 0.05
    late = gt.timestamp_s > 36.0
    err = clock_times(obs, clocks) - gt.timestamp_s
    assert np.ptp(err[late] - np.median(err)) * 10.0 < 0.1  # every camera within 0.1 frame at the end
    # The first segment alone (what windowed reconstruction used before) cannot see the drift.
    seg = np.flatnonzero(obs.stream_index <= 60)
    short = recover_clocks(obs.take(seg), fps=10.0, piecewise=False)
    err_short = clock_times(obs, short) - gt.timestamp_s
    assert np.ptp(err_short[late]) * 10.0 > 0.5


def test_apply_clocks_gives_full_sequencing(recovered):
    obs, gt, clocks = recovered
    full = apply_clocks(obs, clocks)
    assert full.sequencing == "full"
    assert np.all(np.diff(full.timestamp_s) >= 0)
    # Same images, reordered: each keeps its camera, stream index and keypoints.
    t = clock_times(obs, clocks)
    seq = np.argsort(t, kind="stable")
    np.testing.assert_array_equal(full.stream_index, obs.stream_index[seq])
    np.testing.assert_array_equal(full.keypoints_px, obs.keypoints_px[seq])


def test_clocks_file_round_trip(tmp_path, recovered):
    clocks = recovered[2]
    path = clocks.save(tmp_path / "clocks.json")
    back = Clocks.load(path)
    for name in ("cameras", "offset_s", "rate_hz", "drift_ppm", "offset_std_s"):
        np.testing.assert_array_equal(getattr(back, name), getattr(clocks, name))
    with pytest.raises(FileExistsError):
        clocks.save(path)
    clocks.save(path, overwrite=True)
    assert [p.name for p in tmp_path.iterdir()] == ["clocks.json"]  # no temp file left behind
    bad = json.loads(path.read_text())
    bad["cameras"][1]["offset_s"] = "soon"
    path.write_text(json.dumps(bad))
    with pytest.raises(GttNetError, match=r"clocks.json: field 'cameras\[1\].offset_s': expected a number"):
        Clocks.load(path)


def test_bad_inputs_are_one_line_errors(capture, recovered):
    obs = recovered[0]
    none, _ = make_view(capture, "none")
    with pytest.raises(SequencingError, match="frame order"):
        recover_clocks(none)
    with pytest.raises(GttNetError, match="fps: no frame rate for camera 2"):
        recover_clocks(obs, fps={0: 25.0, 1: 30.0})
    with pytest.raises(GttNetError, match="rate must be a positive number"):
        recover_clocks(obs, fps=[25.0, 0.0, 60.0])
    with pytest.raises(GttNetError, match=r"frame_times_s: expected shape"):
        recover_clocks(obs, frame_times_s=np.zeros(3))


def test_time_aware_difference_operator_is_exact_on_quadratics():
    from gttnet.baselines.highpass import difference_operator

    t = np.arange(40) * 0.05 + np.random.default_rng(0).uniform(-0.02, 0.02, 40)  # uneven, never too close
    G = difference_operator(40, 2, timestamp_s=t)
    hbar = np.diff(t).mean()
    np.testing.assert_allclose(G @ (3.0 * t**2 - t + 1.0), 6.0 * hbar**2, rtol=1e-9)
    np.testing.assert_allclose(G @ (5.0 * t - 2.0), 0.0, atol=1e-9)


def test_sync_method_matches_hpf_given_true_timestamps(capture):
    from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
    from gttnet.methods import reconstruct

    obs, gt = make_view(capture, "partial")
    rec = reconstruct(obs, "sync", fps={0: 25.0, 1: 30.0, 2: 60.0})
    full, fgt = make_view(capture, "full")
    ref = reconstruct(full, "hpf", spacing="time", n_folds=3, search="bracket")
    assert rec.sequencing == "partial" and rec.method == "sync"
    assert set(rec.info["clock_offsets_s"]) == {"0", "1", "2"}
    assert mpjpe_mm(rec.points3d, gt.points3d) < 1.1 * mpjpe_mm(ref.points3d, fgt.points3d) + 0.1
    assert kendall_tau(rec.order, gt.global_order) > 0.99


def test_auto_picks_by_sequencing(capture):
    from gttnet.methods import reconstruct

    rates = {0: 25.0, 1: 30.0, 2: 60.0}
    first = {
        "full": "hpf",
        "partial": "sync",
        "none": "gttnet",
    }  # none: the cheap learned model, then stream-sync
    for seq, ran in (("full", "hpf"), ("partial", "sync"), ("none", "stream-sync")):
        obs, _ = make_view(capture, seq)
        opts = {"fps": rates} if seq != "full" else {}
        if seq == "none":
            with pytest.raises(ValueError, match="has no option 'max_iter'"):
                reconstruct(obs, "auto", max_iter=2)  # not an auto option: refused like any unknown option
        rec = reconstruct(obs, "auto", **opts)
        assert rec.method == "auto" and rec.info["auto"]["candidates"][0]["method"] == first[seq]
        if seq != "none":  # with timing the first candidate is decisive on this clean capture
            assert rec.info["method_ran"] == ran


def test_auto_without_sequencing_estimates_the_rates_the_image_counts_get_wrong(capture):
    """The cameras film different spans here: image counts suggest wrong rates, the images do not.

    Before the rates were estimated, stream-sync took them from the image counts, its clocks left 4 px and
    auto fell back on GTT-Net; a too strict gate (relative to the noise) still falls back. ``auto`` runs the
    cheap learned model first, then stream-sync, and keeps the better self-assessed of the two.
    """
    from gttnet.evaluate.metrics import mpjpe_mm
    from gttnet.methods import reconstruct
    from gttnet.sync.method import STREAM_SYNC_MAX_RMS_NOISE
    from gttnet.sync.streams import expected_clock_rms_px

    obs, gt = make_view(capture, "none")
    rec = reconstruct(obs, "auto")
    tried = rec.info["auto"]["candidates"]
    assert [c["method"] for c in tried][:2] == ["gttnet", "stream-sync"]
    ss = reconstruct(obs, "stream-sync")
    assert ss.info["method_ran"] == "stream-sync", ss.info.get("clock_rms_px")
    rates = ss.info["frame_rates"]["cameras"]
    rel = [rates[c]["relative"] * 60.0 / rates["2"]["relative"] for c in ("0", "1", "2")]
    np.testing.assert_allclose(rel, [25.0, 30.0, 60.0], rtol=0.004)
    gate = STREAM_SYNC_MAX_RMS_NOISE * expected_clock_rms_px(ss.info["noise_px"])
    assert ss.info["clock_rms_px"] <= ss.info["gate_px"] == pytest.approx(gate)
    assert mpjpe_mm(ss.points3d, gt.points3d) < mpjpe_mm(reconstruct(obs, "gttnet").points3d, gt.points3d)
    strict = reconstruct(obs, "stream-sync", fps={0: 25.0, 1: 30.0, 2: 60.0}, max_rms_noise=0.2)
    assert strict.info["method_ran"] == "dloe" and strict.info["clock_rms_px"] > strict.info["gate_px"]


def test_simulated_views_carry_each_cameras_own_clock():
    from gttdata.generate_plan import build_sample
    from gttdata.recipe import load_recipe

    recipe = load_recipe("recipes/gttdata/sync.yaml", ["capture.image_drop_rate=0.1"])
    sample = build_sample(recipe, "val", 0)[0]
    obs, gt = make_view(sample, "partial")
    none, _ = make_view(sample, "none")
    assert none.stream_time_s is None and obs.timestamp_s is None
    # Own clock = frame counter / nominal rate: equal to the true time up to each camera's offset (and
    # 100 ppm drift, jitter): the offsets are what remains to recover.
    for c in np.unique(obs.cam_id):
        d = gt.timestamp_s[obs.cam_id == c] - obs.stream_time_s[obs.cam_id == c]
        assert np.ptp(d) < 4e-3 and abs(d.mean()) > 0.01
    clocks = recover_clocks(obs)  # rates and dropped frames come from the views' own clocks
    np.testing.assert_allclose(np.sort(clocks.rate_hz), [25.0, 25.0, 30.0, 60.0], rtol=1e-6)
    assert np.abs(_frame_errors(obs, gt.timestamp_s, clocks)).max() < 0.25


def test_evaluation_records_the_offset_error(capture):
    from gttnet.evaluate.jobs import _offset_error_frames, run_method
    from gttnet.evaluate.recipe import MethodEntry

    obs, gt = make_view(capture, "partial")
    rec = run_method(obs, MethodEntry(method="sync", options={"fps": {0: 25.0, 1: 30.0, 2: 60.0}}))
    err = _offset_error_frames(obs, rec, gt)
    assert err is not None and 0.0 <= err < 0.1
    # Truth moved by half a frame for two of the three cameras: the median over cameras sees it.
    shift = np.select([obs.cam_id == 0, obs.cam_id == 1], [0.5 / 25.0, -0.5 / 30.0], 0.0)
    assert _offset_error_frames(obs, rec, replace(gt, timestamp_s=gt.timestamp_s + shift)) > 0.4
    hpf = run_method(make_view(capture, "full")[0], MethodEntry(method="hpf"))
    assert _offset_error_frames(obs, hpf, gt) is None


def test_count_rates_scale_the_busiest_camera_to_the_top_rate():
    from gttnet.sync.method import count_rates

    cam = np.repeat([4, 1, 2], [100, 50, 25])
    assert count_rates(cam) == {1: 15.0, 2: 7.5, 4: 30.0}
    assert count_rates(cam, top_hz=60.0)[2] == 15.0


def test_stream_sync_without_any_timing_approaches_sync_with_the_streams():
    """No order at all: the streams estimated from the poses, then the clocks, then the smoothness prior."""
    from gttnet.evaluate.metrics import kendall_tau, mpjpe_mm
    from gttnet.methods import reconstruct

    rates = {0: 25.0, 1: 30.0, 2: 60.0}
    cap = _capture(offsets_s=(0.0, 0.3, 0.1), fps=(25.0, 30.0, 60.0), sigma_px=2.0)
    obs, gt = make_view(cap, "none", seed=3)
    rec = reconstruct(obs, "stream-sync", fps=rates)
    assert rec.method == "stream-sync" and rec.info["streams_estimated"] is True
    part, pgt = make_view(cap, "partial")
    bound = mpjpe_mm(reconstruct(part, "sync", fps=rates).points3d, pgt.points3d)
    got = mpjpe_mm(rec.points3d, gt.points3d)
    dloe = mpjpe_mm(reconstruct(obs, "dloe").points3d, gt.points3d)
    assert got < 1.2 * bound + 0.3 and got < 0.5 * dloe  # measured: 3.9, 3.9 and 10.6 mm
    assert kendall_tau(rec.order, gt.global_order) > 0.99
    # given streams are used as they are: the same as sync
    same = reconstruct(part, "stream-sync", fps=rates)
    assert same.info["streams_estimated"] is False
    np.testing.assert_allclose(same.points3d, reconstruct(part, "sync", fps=rates).points3d)


def test_auto_falls_back_on_gttnet_where_a_bundled_model_fits(capture, scene_factory, monkeypatch, tmp_path):
    from gttnet.model import inference
    from gttnet.sync.method import order_free_fallback

    # A toy skeleton: the cross-domain model when it is installed, else DLOE.
    for sequencing in ("none", "partial"):
        assert order_free_fallback(make_view(capture, sequencing)[0]) == "gttnet"
    monkeypatch.setattr(inference, "BUNDLED_POINTNET_MODEL", tmp_path / "absent.pt")
    assert order_free_fallback(make_view(capture, "none")[0]) == "dloe"
    cmu = scene_factory(n_cameras=3, n_joints=31, frames_per_camera=4)
    assert order_free_fallback(make_view(cmu, "none")[0]) == "gttnet"


def test_a_camera_with_too_few_images_for_a_clock_is_left_out(capture):
    from gttnet.methods import reconstruct

    obs, _ = make_view(capture, "none", seed=1)
    keep = np.flatnonzero(obs.cam_id != 2)
    few = obs.take(np.r_[keep, np.flatnonzero(obs.cam_id == 2)[:2]])
    rec = reconstruct(few, "stream-sync", fps={0: 25.0, 1: 30.0, 2: 60.0}, fallback=None)
    assert rec.info["method_ran"] == "stream-sync" and set(rec.info["cameras_left_out"]) == {"2"}
    assert np.isnan(rec.points3d[few.cam_id == 2]).all() and np.isfinite(rec.points3d[few.cam_id != 2]).any()
    assert "camera 2 left out" in rec.info["time_warnings"][0]


def test_auto_with_camera_order_falls_back_when_clocks_cannot_be_recovered(capture):
    """Partial input where two cameras have two images each: no clocks at all; auto still answers."""
    from gttnet.methods import reconstruct

    obs, _ = make_view(capture, "partial", seed=1)
    keep = np.flatnonzero(obs.cam_id == 0)
    few = obs.take(np.r_[keep, np.flatnonzero(obs.cam_id == 1)[:2], np.flatnonzero(obs.cam_id == 2)[:2]])
    with pytest.raises(GttNetError, match="two cameras with a usable stream, 1 left"):
        reconstruct(few, "sync")
    rec = reconstruct(few, "auto")
    tried = rec.info["auto"]["candidates"]
    assert tried[0]["method"] == "sync" and "camera 2: 2 image" in tried[0]["error"]
    # the order-free candidates (a toy skeleton: the cross-domain GTT-Net, then DLOE) answer
    assert rec.info["method_ran"] in ("gttnet", "dloe") and len(tried) == 3
    np.testing.assert_allclose(rec.points3d, reconstruct(few, rec.info["method_ran"]).points3d)
