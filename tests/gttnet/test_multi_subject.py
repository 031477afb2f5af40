"""Two unidentified subjects: identity hiding, virtual images, cannot-link clustering, end to end."""

from __future__ import annotations

import numpy as np
import pytest

from gttnet.apps.multi_subject import (
    cluster_subjects,
    hide_identities,
    reconstruct_subjects,
    score_subjects,
    virtual_images,
)


@pytest.fixture(scope="module")
def capture():
    from gttdata.capture.views import make_view
    from gttdata.generate_plan import build_sample
    from gttdata.recipe import load_recipe

    recipe = load_recipe(
        "recipes/gttdata/multi_subject.yaml",
        ["capture.window_s=1.0", "capture.fps_hz=12", "capture.sigma_px=0"],
    )
    sample = build_sample(recipe, "test", 0)[0]
    return make_view(sample, "none")


def test_hide_identities_shuffles_blocks(capture):
    obs, gt = capture
    sobs, subject = hide_identities(obs, seed=1)
    assert subject.shape == (obs.n_images, 2) and {0, 1} <= set(subject[:, 0])
    swapped = subject[:, 0] == 1
    np.testing.assert_array_equal(sobs.keypoints_px[swapped, :31], obs.keypoints_px[swapped, 31:])
    np.testing.assert_array_equal(sobs.keypoints_px[~swapped, :31], obs.keypoints_px[~swapped, :31])
    v = virtual_images(sobs)
    assert v.n_images == 2 * obs.n_images and v.n_joints == 31 and v.sequencing == "none"
    np.testing.assert_array_equal(v.cam_id[::2], obs.cam_id)


def test_cluster_subjects_two_chains_with_cannot_link():
    n = 40
    rng = np.random.default_rng(0)
    subject = np.stack([rng.permutation(2) for _ in range(n)])  # subject of block k of image n
    A = np.zeros((2 * n, 2 * n))
    order = rng.permutation(n)
    for s in range(2):
        v = np.array([2 * i + int(np.flatnonzero(subject[i] == s)[0]) for i in order])
        A[v[:-1], v[1:]] = A[v[1:], v[:-1]] = 1.0
    A[0, 5] = A[5, 0] = 0.01  # one spurious link
    labels = cluster_subjects(A, n)
    assert np.all(np.sort(labels, axis=1) == [0, 1])
    acc = np.mean(labels == subject)
    assert max(acc, 1 - acc) == 1.0


def test_two_subjects_end_to_end_noise_free(capture):
    obs, gt = capture
    sobs, subject = hide_identities(obs, seed=3)
    res = reconstruct_subjects(sobs, method="dloe")
    sc = score_subjects(res, subject, gt.points3d)
    assert sc["clustering_accuracy"] >= 0.95
    assert max(sc["mpjpe_mm"]) < 80.0
    assert res.points3d.shape == (obs.n_images, 2, 31, 3)


def test_only_two_subjects(capture):
    obs, _ = capture
    with pytest.raises(ValueError, match="only 2"):
        reconstruct_subjects(obs, n_subjects=3)
