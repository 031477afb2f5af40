"""The decorrelated-motion control keeps every joint trajectory's shape but breaks the body."""

from __future__ import annotations

import numpy as np

from gttdata.augment import decorrelate, get_augmentation
from gttdata.mocap.procedural import generate_motion


def _pairwise(x):
    return np.linalg.norm(x[:, :, None] - x[:, None, :], axis=-1)


def test_each_trajectory_moves_rigidly_and_bones_break():
    walk = generate_motion("walk", seed=1, duration_s=2.0)
    out = decorrelate(walk, np.random.default_rng(0), max_angle_deg=90.0, max_shift_m=0.3)
    a, b = walk.positions, out.positions
    # Rigid per joint: distances between any two instants of one joint's trajectory are preserved.
    da = np.linalg.norm(a[:, None] - a[None], axis=-1)
    db = np.linalg.norm(b[:, None] - b[None], axis=-1)
    np.testing.assert_allclose(db, da, atol=1e-9)
    # ...but not as one body: bone lengths now change over time.
    assert out.bone_lengths().std(axis=0).max() > 1e-3
    assert walk.bone_lengths().std(axis=0).max() < 1e-9


def test_prob_zero_is_identity_and_draws_nothing():
    walk = generate_motion("walk", seed=1, duration_s=1.0)
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    assert decorrelate(walk, rng, prob=0.0) is walk
    assert rng.bit_generator.state == state


def test_registered_and_deterministic():
    walk = generate_motion("jog", seed=2, duration_s=1.0)
    fn = get_augmentation("decorrelate").fn
    x = fn(walk, np.random.default_rng(3)).positions
    y = fn(walk, np.random.default_rng(3)).positions
    np.testing.assert_array_equal(x, y)
    assert not np.allclose(_pairwise(x[:1]), _pairwise(walk.positions[:1]))
