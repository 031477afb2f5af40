"""Tests of the procedural motion source: kinematic validity, ground contact, smoothness, determinism."""

from __future__ import annotations

import functools
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gttdata.mocap.motion import Motion
from gttdata.mocap.procedural import PROCEDURAL_KINDS, generate_motion, random_motion
from gttdata.skeleton import cmu31

SK = cmu31()
FEET = [SK.index(n) for n in ("lfoot", "ltoes", "rfoot", "rtoes")]
GROUNDED_KINDS = ("walk", "turn", "gesture", "idle", "dance")


@functools.cache
def _motion(kind: str, seed: int = 0) -> Motion:
    """10 s at 120 Hz, cached: the motions are pure functions of their arguments."""
    return generate_motion(kind, seed=seed)


def _speeds(m: Motion) -> np.ndarray:
    """Joint speeds between consecutive frames, m/s, shape (T - 1, J)."""
    return np.linalg.norm(np.diff(m.positions, axis=0), axis=-1) * m.fps_hz


def test_kinds_cover_the_required_set():
    assert {"walk", "run", "jog", "turn", "jump", "gesture", "dance", "idle", "mixed"} <= set(
        PROCEDURAL_KINDS
    )


def test_unknown_kind_lists_the_kinds():
    with pytest.raises(ValueError, match="walk.*mixed"):
        generate_motion("moonwalk", seed=0)


@pytest.mark.parametrize(
    "kwargs",
    [{"seed": -1}, {"seed": 1.5}, {"seed": 0, "duration_s": 0.0}, {"seed": 0, "fps_hz": 0.0},
     {"seed": 0, "speed_scale": 5.0}, {"seed": 0, "body_scale": 0.1}, {"seed": 0, "duration_s": float("nan")}],
)  # fmt: skip
def test_bad_arguments_raise(kwargs):
    with pytest.raises(ValueError):
        generate_motion("walk", **kwargs)


@pytest.mark.parametrize("kind", PROCEDURAL_KINDS)
def test_output_contract(kind):
    m = _motion(kind)
    assert m.positions.shape == (1201, 31, 3)
    assert m.fps_hz == 120.0 and m.skeleton == SK
    assert m.name == f"procedural/{kind}/s0"
    assert (
        m.provenance["source"] == "procedural" and m.provenance["kind"] == kind and m.provenance["seed"] == 0
    )
    assert np.isfinite(m.positions).all()


@pytest.mark.parametrize("duration_s, fps_hz, frames", [(2.0, 30.0, 61), (0.5, 120.0, 61), (3.3, 100.0, 331)])
def test_frame_count_follows_duration_and_rate(duration_s, fps_hz, frames):
    m = generate_motion("walk", seed=1, duration_s=duration_s, fps_hz=fps_hz)
    assert m.n_frames == frames and m.fps_hz == fps_hz


def test_ten_second_walk_keeps_bone_lengths_to_1e9():
    assert _motion("walk").bone_lengths().std(axis=0).max() < 1e-9


@pytest.mark.parametrize("kind", PROCEDURAL_KINDS)
def test_bone_lengths_constant_and_plausible(kind):
    lengths = _motion(kind, 1).bone_lengths()
    assert lengths.std(axis=0).max() < 1e-9
    femur = lengths[0, list(map(tuple, SK.bones)).index((SK.index("ltibia"), SK.index("lfemur")))]
    assert 0.33 < femur < 0.5


@pytest.mark.parametrize("kind", GROUNDED_KINDS)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_feet_on_the_floor_when_standing_or_walking(kind, seed):
    foot_z = _motion(kind, seed).positions[:, FEET, 2]
    assert abs(foot_z.min()) < 0.03
    # Some foot touches the floor in every frame (ankle ~7 cm, toe ~2 cm above it when flat).
    assert foot_z.min(axis=1).max() < 0.09


@pytest.mark.parametrize("kind", PROCEDURAL_KINDS)
def test_feet_never_sink_below_the_floor(kind):
    for seed in (0, 1):
        assert _motion(kind, seed).positions[:, FEET, 2].min() > -0.03


@pytest.mark.parametrize("kind, limit_mps", [("walk", 6.0), ("turn", 6.0), ("jog", 12.0), ("run", 12.0)])
def test_joint_speed_is_human(kind, limit_mps):
    for seed in (0, 1, 2):
        assert _speeds(_motion(kind, seed)).max() < limit_mps


@pytest.mark.parametrize("kind", PROCEDURAL_KINDS)
def test_no_velocity_spikes(kind):
    for seed in (0, 1):
        m = _motion(kind, seed)
        assert _speeds(m).max() < 12.0
        acc = np.linalg.norm(np.diff(m.positions, 2, axis=0), axis=-1) * m.fps_hz**2
        assert acc.max() < 500.0  # m/s^2; a velocity jump of 1 m/s in one frame would read 120 m/s^2 * 1/dt
        # Jerk-free seams: no frame's acceleration towers over its neighbourhood's.
        a = acc.max(axis=1)
        local = np.convolve(a, np.ones(25) / 25, mode="same")
        assert (a <= 6.0 * local + 5.0).all()


@pytest.mark.parametrize("kind", ["walk", "jog", "run", "turn"])
def test_no_frame_to_frame_jump_in_gaits(kind):
    step = np.linalg.norm(np.diff(_motion(kind).positions, axis=0), axis=-1).max(axis=1)
    assert step.max() < 4.0 * np.median(step)


def _planted_slips(m: Motion, ankle_tol: float = 0.015) -> list[float]:
    """Horizontal toe displacement over each run of >= 6 frames with that foot on the floor, metres.

    The toe joint must be within 1.5 cm of its lowest height, the ankle within ``ankle_tol`` of its
    own (runners land on the forefoot, so their heels never come fully down).
    """
    p = m.positions
    slips = []
    for ankle, toe in ((SK.index("lfoot"), SK.index("ltoes")), (SK.index("rfoot"), SK.index("rtoes"))):
        za, zt = p[:, ankle, 2], p[:, toe, 2]
        flat = (za < np.percentile(za, 2) + ankle_tol) & (zt < np.percentile(zt, 2) + 0.015)
        edges = np.flatnonzero(np.diff(np.concatenate(([0], flat.astype(np.int8), [0]))))
        for a, b in zip(edges[::2], edges[1::2], strict=True):
            if b - a >= 6:
                slips.append(float(np.linalg.norm(p[b - 1, toe, :2] - p[a, toe, :2])))
    return slips


@pytest.mark.parametrize("kind", ["walk", "jog", "run", "turn", "idle", "gesture", "jump"])
def test_planted_feet_do_not_skate(kind):
    tol = 0.06 if kind == "run" else 0.015
    slips = [s for seed in (0, 1, 2) for s in _planted_slips(_motion(kind, seed), tol)]
    assert slips and np.median(slips) < 0.03 and max(slips) < 0.06


@pytest.mark.parametrize("kind", ["walk", "jog", "run"])
def test_gaits_travel(kind):
    root = _motion(kind).positions[:, 0, :2]
    assert np.linalg.norm(root[-1] - root[0]) > 2.0
    assert np.linalg.norm(np.diff(root, axis=0), axis=-1).sum() > 2.0


def test_running_and_jumping_have_flight_phases():
    run_low = _motion("run").positions[:, FEET, 2].min(axis=1)
    assert (run_low > 0.06).mean() > 0.05
    jump_low = np.concatenate([_motion("jump", s).positions[:, FEET, 2].min(axis=1) for s in (1, 2)])
    assert jump_low.max() > 0.2


def test_turn_changes_heading():
    root = _motion("turn").positions[:, 0, :2]
    v = np.diff(root[::60], axis=0)
    ang = np.unwrap(np.arctan2(v[:, 1], v[:, 0]))
    assert np.ptp(ang) > np.deg2rad(45)


def test_same_seed_bit_identical_and_other_seed_different():
    a = generate_motion("mixed", seed=7, duration_s=3.0)
    b = generate_motion("mixed", seed=7, duration_s=3.0)
    c = generate_motion("mixed", seed=8, duration_s=3.0)
    assert np.array_equal(a.positions, b.positions)
    assert not np.allclose(a.positions, c.positions)


def _descriptor(m: Motion) -> np.ndarray:
    """A few motion statistics in metres and m/s: speed, bounce, arm height and activity, crouch."""
    p = m.positions
    rel = p - p[:, :1]
    wrists = rel[:, [SK.index("lwrist"), SK.index("rwrist")], 2]
    leg = np.linalg.norm(p[:, SK.index("lfemur")] - p[:, SK.index("lfoot")], axis=-1)
    root_speed = np.linalg.norm(np.diff(p[:, 0, :2], axis=0), axis=-1).mean() * m.fps_hz
    return np.array(
        [root_speed, p[:, 0, 2].std(), wrists.max(), wrists.std(), _speeds(m)[:, 20].mean(), leg.std()]
    )


def test_kinds_differ():
    kinds = ("walk", "run", "jump", "gesture", "dance", "idle")
    d = {k: _descriptor(_motion(k, 1)) for k in kinds}
    for i, a in enumerate(kinds):
        for b in kinds[i + 1 :]:
            assert np.linalg.norm(d[a] - d[b]) > 0.05, (a, b)


def test_seeds_vary_subject_and_speed():
    ms = [_motion("walk", s) for s in range(4)]
    statures = [m.provenance["stature_m"] for m in ms]
    speeds = [m.provenance["speed_mps"] for m in ms]
    assert np.ptp(statures) > 0.05 and np.ptp(speeds) > 0.1


@pytest.mark.parametrize("seed", range(6))
def test_stature_in_human_range(seed):
    m = _motion("idle", seed)
    stature = m.provenance["stature_m"]
    assert 1.45 <= stature <= 2.0
    head = m.positions[:, SK.index("head"), 2]
    assert 0.78 * stature < np.median(head) < 0.93 * stature


def test_body_and_speed_scale_are_honoured():
    tall = generate_motion("walk", seed=3, duration_s=4.0, body_scale=1.1)
    short = generate_motion("walk", seed=3, duration_s=4.0, body_scale=0.9)
    assert tall.provenance["stature_m"] > short.provenance["stature_m"] + 0.2
    slow = generate_motion("walk", seed=3, duration_s=4.0, speed_scale=0.7)
    fast = generate_motion("walk", seed=3, duration_s=4.0, speed_scale=1.3)

    def path(m):
        return np.linalg.norm(np.diff(m.positions[:, 0, :2], axis=0), axis=-1).sum()

    assert path(fast) > 1.3 * path(slow)


@pytest.mark.parametrize("kind", ["walk", "run", "turn", "idle", "gesture", "jump"])
def test_left_is_on_the_subjects_left(kind):
    p = _motion(kind).positions
    # Facing direction from the feet (ankle to toes), which holds for every kind.
    fwd = (p[:, SK.index("ltoes")] - p[:, SK.index("lfoot")]) + (
        p[:, SK.index("rtoes")] - p[:, SK.index("rfoot")]
    )
    left = np.stack([-fwd[:, 1], fwd[:, 0]], axis=1)
    hips = p[:, SK.index("lfemur"), :2] - p[:, SK.index("rfemur"), :2]
    assert ((hips * left).sum(axis=1) > 0).mean() > 0.99


@pytest.mark.parametrize("seed", [0, 2])
def test_walk_heads_where_it_goes(seed):
    m = _motion("walk", seed)
    p = m.positions
    v = np.diff(p[::30, 0, :2], axis=0)
    hips = (p[::30, SK.index("lfemur"), :2] - p[::30, SK.index("rfemur"), :2])[:-1]
    left = np.stack([-v[:, 1], v[:, 0]], axis=1)
    facing = -1.0 if m.provenance["variant"] == "backward" else 1.0
    assert (facing * (hips * left).sum(axis=1) > 0).all()


def test_walk_variants_occur():
    variants = {generate_motion("walk", seed=s, duration_s=0.5).provenance["variant"] for s in range(40)}
    assert {"normal", "backward", "crouched", "carrying", "uneven"} <= variants


def test_random_motion_is_generate_motion_of_a_drawn_kind():
    m = random_motion(11, duration_s=2.0)
    assert np.array_equal(
        m.positions, generate_motion(m.provenance["kind"], seed=11, duration_s=2.0).positions
    )
    kinds = {random_motion(s, duration_s=0.5, kinds=("walk", "jump")).provenance["kind"] for s in range(12)}
    assert kinds == {"walk", "jump"}
    with pytest.raises(ValueError, match="unknown"):
        random_motion(0, kinds=("walk", "fly"))
    with pytest.raises(ValueError):
        random_motion(0, kinds=())


def test_short_and_low_rate_motions_work_for_every_kind():
    for kind in PROCEDURAL_KINDS:
        m = generate_motion(kind, seed=5, duration_s=1.0, fps_hz=30.0)
        assert m.n_frames == 31 and m.bone_lengths().std(axis=0).max() < 1e-9


@settings(max_examples=15, deadline=None)
@given(
    kind=st.sampled_from(PROCEDURAL_KINDS),
    seed=st.integers(0, 2**63 - 1),
    duration_s=st.floats(0.2, 4.0),
    fps_hz=st.sampled_from([25.0, 30.0, 50.0, 120.0]),
)
def test_invariants_hold_for_any_seed_duration_and_rate(kind, seed, duration_s, fps_hz):
    m = generate_motion(kind, seed=seed, duration_s=duration_s, fps_hz=fps_hz)
    assert m.n_frames == int(round(duration_s * fps_hz)) + 1
    assert m.bone_lengths().std(axis=0).max() < 1e-9
    assert m.positions[:, FEET, 2].min() > -0.03
    assert _speeds(m).max() < 12.0
    assert 1.45 <= m.provenance["stature_m"] <= 2.0


def test_generation_is_fast():
    generate_motion("mixed", seed=0, duration_s=1.0)
    t0 = time.perf_counter()
    generate_motion("mixed", seed=1)
    assert time.perf_counter() - t0 < 1.0  # typically ~0.03 s; loose for loaded CI machines


@pytest.mark.parametrize("kind", ["walk", "climb", "sit"])
def test_monkey_motions_are_deterministic_above_the_floor_and_on_their_topology(kind):
    from gttdata.mocap.procedural import generate_monkey_motion, generate_skeleton_motion
    from gttdata.skeletons import skeleton_family

    m = generate_monkey_motion(kind, seed=4, duration_s=3.0, fps_hz=60.0)
    again = generate_skeleton_motion("monkey13", kind, seed=4, duration_s=3.0, fps_hz=60.0)
    np.testing.assert_array_equal(m.positions, again.positions)
    assert m.skeleton.name == "monkey13" and skeleton_family("monkey13") == "primate"
    assert m.positions.shape == (181, 13, 3) and np.isfinite(m.positions).all()
    assert m.positions[..., 2].min() >= -1e-9
    # Rigid segments (all but shoulder -> hand, which has no elbow) keep their lengths.
    sk = m.skeleton
    arms = {sk.index("left_hand"), sk.index("right_hand")}
    bl = m.bone_lengths()
    rigid = [k for k, (c, _) in enumerate(sk.bones) if c not in arms]
    assert bl[:, rigid].std(axis=0).max() < 0.03
    hip, neck = sk.index("hip"), sk.index("neck")
    trunk = np.linalg.norm(m.positions[:, neck] - m.positions[:, hip], axis=-1).mean()
    assert 0.15 < trunk < 0.5  # macaque-sized


def test_a_climbing_monkey_goes_up_and_a_walking_one_stays_low():
    from gttdata.mocap.procedural import generate_monkey_motion

    climb = generate_monkey_motion("climb", seed=2, duration_s=4.0, fps_hz=30.0)
    walk = generate_monkey_motion("walk", seed=2, duration_s=4.0, fps_hz=30.0)
    hip = climb.skeleton.index("hip")
    rise = climb.positions[-1, hip, 2] - climb.positions[0, hip, 2]
    assert 0.1 < rise and climb.positions[..., 2].max() < 2.5  # it climbs, and stays in a cage's height
    assert walk.positions[..., 2].max() < 0.8
    neck = climb.skeleton.index("neck")
    up = climb.positions[:, neck] - climb.positions[:, hip]
    assert np.mean(up[:, 2] / np.linalg.norm(up, axis=-1)) > 0.8  # body axis points up the wall
