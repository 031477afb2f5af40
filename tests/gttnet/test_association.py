"""Several people across unsynchronized cameras (``gttnet.association``)."""

from __future__ import annotations

import numpy as np
import pytest

from gttdata.generate_plan import build_sample
from gttdata.recipe import load_recipe, parse_recipe, recipe_to_dict
from gttnet.association import CameraPeople, associate, track_camera


@pytest.fixture(scope="module")
def two_people():
    """A two-subject capture (4 cameras, 30 Hz, staggered clocks), as per-camera detection lists."""
    data = recipe_to_dict(load_recipe("recipes/gttdata/multi_subject.yaml"))
    data["augmentations"] = []
    recipe = parse_recipe(data)
    s = build_sample(recipe, "test", 0)[0]
    return s


def _camera_rig(sample):
    from gttdata.cameras import Camera

    cams = []
    for v in range(int(sample.cam_id.max()) + 1):
        n = int(np.flatnonzero(sample.cam_id == v)[0])
        w, h = sample.image_size[v]
        cams.append(
            Camera(
                name=f"cam{v}",
                K=sample.K[n],
                cam_from_world=sample.cam_from_world[n],
                image_size=(int(w), int(h)),
            )
        )
    return cams


def _detections(sample, *, bystander_frac: float = 0.0, seed: int = 0, late: tuple[int, ...] = (0, 0, 0, 0)):
    """Per camera: both people in every frame, in random order; optionally a bystander in one camera.

    ``late``: frames by which each camera's counter is late (cameras started by hand).
    """
    rng = np.random.default_rng(seed)
    J = sample.skeleton.n_joints // 2
    people, truth = [], []
    for v in range(int(sample.cam_id.max()) + 1):
        rows = np.flatnonzero(sample.cam_id == v)
        frame, kp, who = [], [], []
        for n in rows:
            persons = [(0, sample.keypoints_px[n, :J]), (1, sample.keypoints_px[n, J:])]
            if v == 1 and rng.random() < bystander_frac:
                # Someone else, confidently detected, walking by in front of camera 1 only.
                persons.append((2, sample.keypoints_px[n, :J] + np.array([180.0, 40.0])))
            for k in rng.permutation(len(persons)):
                pid, p = persons[k]
                if np.isfinite(p).all(axis=-1).sum() < 3:
                    continue  # a detector reports nobody there
                frame.append(int(sample.stream_index[n]) + late[v])
                kp.append(p)
                who.append(pid)
        kp = np.asarray(kp, dtype=np.float64)
        score = np.where(np.isfinite(kp).all(axis=-1), 0.9, 0.0)
        score[np.asarray(who) == 2] = 0.99
        people.append(CameraPeople(np.asarray(frame), kp, score))
        truth.append(np.asarray(who))
    return people, truth


def test_tracks_follow_people_through_a_camera(two_people):
    people, truth = _detections(two_people)
    ids = track_camera(people[0])
    for t in np.unique(ids):  # every track holds one person only: no identity switch
        assert len(np.unique(truth[0][ids == t])) == 1


@pytest.mark.parametrize("late", [(0, 0, 0, 0), (0, 5, 12, 3)])
def test_both_people_are_found_without_switches_and_the_bystander_never_wins(two_people, late):
    people, truth = _detections(two_people, bystander_frac=0.1, late=late)
    cams = _camera_rig(two_people)
    fps = [30.0] * len(cams)
    subjects = associate(people, cams, fps, n_subjects=2)
    assert len(subjects) == 2
    found = []
    for s in subjects:
        ids = np.concatenate([truth[v][rows] for v, rows in enumerate(s.detections)])
        assert len(np.unique(ids)) == 1, np.unique(ids, return_counts=True)  # 0 identity switches
        found.append(int(ids[0]))
        # Every camera contributes nearly all of that person's frames.
        for v, rows in enumerate(s.detections):
            assert rows.size >= 0.9 * int(np.sum(truth[v] == ids[0]))
    assert sorted(found) == [0, 1]
    one = associate(people, cams, fps, n_subjects=1)
    assert len(one) == 1 and np.concatenate([truth[v][r] for v, r in enumerate(one[0].detections)]).max() < 2


def test_a_person_seen_by_one_camera_is_not_a_subject(two_people):
    people, truth = _detections(two_people)
    cams = _camera_rig(two_people)
    only_one = [people[0]] + [
        CameraPeople(p.frame[t == 0], p.keypoints_px[t == 0], p.score[t == 0])
        for p, t in zip(people[1:], truth[1:], strict=True)
    ]
    subjects = associate(only_one, cams, [30.0] * len(cams), n_subjects=2)
    assert len(subjects) == 1  # person 1 appears in camera 0 only


def test_mismatched_inputs_are_one_line(two_people):
    people, _ = _detections(two_people)
    with pytest.raises(ValueError, match="4 cameras of detections, 1 cameras"):
        associate(people, _camera_rig(two_people)[:1], [30.0])
