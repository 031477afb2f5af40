"""Observations refuses inputs every solver would fail on later, each with one line naming the field."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gttdata.capture.views import make_view
from gttdata.errors import KeypointFormatError, SequencingError


@pytest.fixture
def views(scene_factory):
    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=1.0, missing=0.2, seed=1)
    return {s: make_view(sample, s, seed=0)[0] for s in ("none", "full")}


def test_nan_pixels_of_a_visible_joint_are_named(views):
    obs = views["none"]
    i, p = (int(x) for x in np.argwhere(obs.visible)[3])
    px = obs.keypoints_px.copy()
    px[i, p, 1] = np.inf
    with pytest.raises(KeypointFormatError) as exc:
        dataclasses.replace(obs, keypoints_px=px)
    msg = str(exc.value)
    assert msg.startswith(
        "keypoints_px: expected finite pixels for every visible joint, found NaN or inf in 1"
    )
    assert f"image {i}, joint {p} {obs.skeleton.joint_names[p]!r}" in msg and "\n" not in msg


def test_nan_pixels_of_a_missing_joint_are_fine(views):
    obs = views["none"]
    px = obs.keypoints_px.copy()
    px[~obs.visible] = np.nan
    assert dataclasses.replace(obs, keypoints_px=px).n_images == obs.n_images


def test_visible_mask_must_match_keypoints(views):
    obs = views["none"]
    with pytest.raises(
        ValueError, match=r"visible must have shape \(18, 5\) like keypoints_px, got \(18, 4\)"
    ):
        dataclasses.replace(obs, visible=obs.visible[:, :4])


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda t: np.zeros_like(t), r"all 18 timestamps are 0.0 s, which orders nothing"),
        (lambda t: np.where(np.arange(t.size) == 2, np.nan, t), r"timestamp_s: expected 18 finite times"),
    ],
)
def test_full_timestamps_must_order_something(views, edit, match):
    obs = views["full"]
    with pytest.raises(SequencingError, match=match):
        dataclasses.replace(obs, timestamp_s=edit(obs.timestamp_s))
