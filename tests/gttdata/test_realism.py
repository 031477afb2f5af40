"""Pan-tilt-zoom cameras and detector habits in simulated captures (``gttdata.capture.realism``)."""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.errors import RecipeError
from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe, parse_recipe, recipe_hash, recipe_to_dict


def _recipe(**capture):
    data = recipe_to_dict(load_recipe("recipes/gttdata/tiny.yaml"))
    data["augmentations"] = []
    data["splits"][0]["sources"][0]["duration_s"] = 10.0
    data["capture"].update({"window_s": 3.0, "fps_hz": 30.0, **capture})
    return parse_recipe(data)


def _sample(**capture):
    return build_sample(_recipe(**capture), "train", 0)[0]


def test_realism_fields_leave_older_recipes_and_samples_unchanged():
    plain = _recipe()
    d = recipe_to_dict(plain)
    for key in ("ptz_prob", "ptz_lag_s", "swap_rate", "noise_corr_s", "miss_run_frames"):
        assert key not in d["capture"]  # not in the plain form at its default: the hash is unchanged
    assert recipe_hash(plain) != recipe_hash(_recipe(swap_rate=0.1))
    assert "swap_rate" not in _sample().meta["capture"]


def test_ptz_cameras_stay_in_place_and_turn_after_the_subject():
    fixed, ptz = _sample(), _sample(ptz_prob=1.0, ptz_lag_s=0.0, ptz_aim_deg=0.0)
    np.testing.assert_allclose(ptz.points3d, fixed.points3d)

    def centres(s):
        return np.einsum("nba,nb->na", s.cam_from_world[:, :3, :3], -s.cam_from_world[:, :3, 3])

    np.testing.assert_allclose(centres(ptz), centres(fixed), atol=1e-9)  # pan and tilt, no travel
    for v in np.unique(ptz.cam_id):
        R = ptz.cam_from_world[ptz.cam_id == v, :3, :3]
        assert np.ptp(R.reshape(len(R), -1), axis=0).max() > 1e-3  # a pose per image
    # With no lag and no aiming error the subject's centre projects onto the principal point.
    c = ptz.points3d.mean(axis=1)
    Xc = np.einsum("nab,nb->na", ptz.cam_from_world[:, :3, :3], c) + ptz.cam_from_world[:, :3, 3]
    h = np.einsum("nab,nb->na", ptz.K, Xc)
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], ptz.K[:, :2, 2], atol=1e-6)


def test_ptz_zoom_keeps_the_subject_at_the_asked_height():
    s = _sample(ptz_prob=1.0, ptz_lag_s=0.0, ptz_aim_deg=0.0, ptz_subject_px=120.0, sigma_px=0.0)
    px = s.keypoints_gt_px
    centre = px.mean(axis=1, keepdims=True)
    extent = 2.0 * np.linalg.norm(px - centre, axis=-1).max(axis=1)
    assert np.median(extent) == pytest.approx(120.0, rel=0.15)
    assert np.ptp(s.K[:, 0, 0]) > 0  # the focal length follows the subject's distance


def test_correlated_noise_drifts_along_each_stream_with_the_same_spread():
    s = _sample(sigma_px=3.0, noise_corr_s=0.5, joint_drop_rate=0.0)
    e = (s.keypoints_px - s.keypoints_gt_px)[s.visible]
    assert np.nanstd(e) == pytest.approx(3.0, rel=0.2)
    err = s.keypoints_px - s.keypoints_gt_px
    lag1 = []
    for v in np.unique(s.cam_id):
        rows = np.flatnonzero(s.cam_id == v)[np.argsort(s.timestamp_s[s.cam_id == v])]
        a, b = err[rows[:-1], :, 0].ravel(), err[rows[1:], :, 0].ravel()
        ok = np.isfinite(a) & np.isfinite(b)
        lag1.append(np.corrcoef(a[ok], b[ok])[0, 1])
    assert min(lag1) > 0.8  # exp(-(1/30)/0.5) = 0.94; independent noise gives ~0
    indep = _sample(sigma_px=3.0, joint_drop_rate=0.0)
    d = indep.keypoints_px - indep.keypoints_gt_px
    rows = np.flatnonzero(indep.cam_id == 0)
    a, b = d[rows[:-1], :, 0].ravel(), d[rows[1:], :, 0].ravel()
    ok = np.isfinite(a) & np.isfinite(b)
    assert abs(np.corrcoef(a[ok], b[ok])[0, 1]) < 0.2


def test_left_right_swaps_mirror_whole_images():
    s = _sample(sigma_px=0.0, swap_rate=0.3, joint_drop_rate=0.0)
    mirror = list(s.skeleton.mirror)
    swapped = np.all(
        np.isclose(s.keypoints_px, s.keypoints_gt_px[:, mirror]) | np.isnan(s.keypoints_px), axis=(1, 2)
    )
    straight = np.all(np.isclose(s.keypoints_px, s.keypoints_gt_px) | np.isnan(s.keypoints_px), axis=(1, 2))
    assert np.all(swapped | straight)
    assert int((swapped & ~straight).sum()) <= s.meta["n_swapped_images"]
    full = s.visible.all(axis=1)  # where every joint is seen, a swap always shows
    assert full.sum() > 20
    assert 0.15 < (swapped & ~straight)[full].mean() < 0.45
    assert 0.15 < s.meta["n_swapped_images"] / s.n_images < 0.45


def test_missed_joints_come_in_runs_at_the_asked_rate():
    def missing_and_runs(s):
        runs = []
        for v in np.unique(s.cam_id):
            rows = np.flatnonzero(s.cam_id == v)[np.argsort(s.timestamp_s[s.cam_id == v])]
            m = ~s.visible[rows]
            for j in range(m.shape[1]):
                col = np.concatenate([[False], m[:, j], [False]]).astype(int)
                starts, ends = np.flatnonzero(np.diff(col) == 1), np.flatnonzero(np.diff(col) == -1)
                runs.extend(ends - starts)
        return float((~s.visible).mean()), float(np.mean(runs))

    # Missing joints include those out of the image: compare with independent drops at the same rate.
    run_missing, run_len = missing_and_runs(_sample(joint_drop_rate=0.3, miss_run_frames=10.0, window_s=8.0))
    ind_missing, ind_len = missing_and_runs(_sample(joint_drop_rate=0.3, window_s=8.0))
    assert run_missing == pytest.approx(ind_missing, abs=0.08)
    assert run_len > 2.5 * ind_len


def test_out_of_range_ptz_probability_is_one_line():
    with pytest.raises(RecipeError, match="ptz_prob") as exc:
        _recipe(ptz_prob=1.5)
    assert "\n" not in str(exc.value)


def test_ptz_probability_mixes_fixed_and_following_cameras():
    recipe = _recipe(ptz_prob=0.5)
    picks = [("train", i) for i in range(4)] + [("val", 0), ("val", 1), ("test", 0), ("test", 1)]
    kinds = [build_sample(recipe, sp, i)[0].meta["capture"].get("camera_motion", "fixed") for sp, i in picks]
    assert set(kinds) == {"ptz", "fixed"}, kinds
