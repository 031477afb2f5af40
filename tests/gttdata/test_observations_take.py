"""Observations.take: one subset of images with every per-image field indexed alike."""

from __future__ import annotations

import dataclasses

import numpy as np

from gttdata.capture.views import PER_IMAGE_FIELDS, Observations, make_view


def test_take_indexes_every_per_image_field(scene_factory):
    sample = scene_factory(n_cameras=3, n_joints=5, frames_per_camera=6, sigma_px=1.0, missing=0.2, seed=1)
    obs, _ = make_view(sample, "full", seed=0)
    n, j = obs.n_images, obs.n_joints
    obs = dataclasses.replace(
        obs, stream_time_s=np.arange(n, dtype=float), confidence=np.linspace(0, 1, n * j).reshape(n, j)
    )
    rows = np.array([4, 0, 7, 2])
    sub = obs.take(rows)
    for name in PER_IMAGE_FIELDS:
        np.testing.assert_array_equal(getattr(sub, name), np.asarray(getattr(obs, name))[rows], err_msg=name)
    np.testing.assert_array_equal(sub.image_size, obs.image_size)  # per camera, not per image
    assert sub.sequencing == obs.sequencing and sub.skeleton is obs.skeleton


def test_per_image_fields_are_every_field_with_an_image_axis():
    names = {f.name for f in dataclasses.fields(Observations)}
    assert set(PER_IMAGE_FIELDS) == names - {"sequencing", "skeleton", "image_size"}
