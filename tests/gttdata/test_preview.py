"""Tests of gttdata.preview: the 3-D renderer agrees with Camera.project, overlays, contact sheets, plots, CLI.

The 3-D tests need an offscreen GL backend (Mesa EGL or OSMesa, see scripts/gl_deps.sh) and skip with the
backend errors as the reason where none works.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from gttdata.cameras import Camera, look_at
from gttdata.capture.sample import CaptureSample
from gttdata.cli import main
from gttdata.generate_plan import build_sample
from gttdata.preview import _gl
from gttdata.preview._style import (
    CENTRE,
    LEFT,
    RIGHT,
    SIDE_RGB,
    joint_rgb,
    joint_sides,
    joint_subjects,
    side_bgr_u8,
)
from gttdata.preview.overlay import (
    MAX_SHEET_WIDTH_PX,
    MISSING_BGR,
    contact_sheet,
    contact_sheets,
    draw_overlay,
    motion_label,
    sheet_columns,
    write_video,
)
from gttdata.preview.render import (
    front_azimuth_deg,
    opengl_camera_pose,
    render_joint_labels,
    render_samples,
    render_view,
)
from gttdata.recipe import load_recipe
from gttdata.skeleton import Skeleton, cmu31

TINY = "recipes/gttdata/tiny.yaml"


@pytest.fixture(scope="module")
def tiny_sample() -> CaptureSample:
    """Sample 0 of the tiny recipe's train split: CMU-31 jog, 3 cameras 3 m away, 24 images, 10 % dropout."""
    return build_sample(load_recipe(TINY), "train", 0)[0]


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory):
    """The tiny recipe generated into a temporary dataset directory (8 samples, manifest included)."""
    from gttdata.generation import generate_dataset

    root = tmp_path_factory.mktemp("tiny")
    recipe = dataclasses.replace(load_recipe(TINY), output_dir=str(root))
    generate_dataset(recipe, progress=False)
    return root


@pytest.fixture(scope="module")
def gl():
    """Skip unless an offscreen GL backend works (the reason lists each backend's error)."""
    try:
        _gl.offscreen_renderer(8, 8)
    except (_gl.RendererUnavailableError, _gl.PreviewDependencyError) as exc:
        pytest.skip(f"no offscreen GL: {exc}")


def _shuffled(sample: CaptureSample, seed: int = 0) -> CaptureSample:
    """The same capture stored in a random image order (timestamps untouched)."""
    p = np.random.default_rng(seed).permutation(sample.n_images)
    per_image = ("cam_id", "timestamp_s", "stream_index", "global_order", "keypoints_px", "visible")
    per_image += ("keypoints_gt_px", "K", "cam_from_world", "points3d", "affinity_w")
    return sample.replace(
        **{k: getattr(sample, k)[p] for k in per_image}, affinity_nbr=sample.affinity_nbr[p]
    )


def _check_label_centroids(points: np.ndarray, cam: Camera, radius_m: float) -> int:
    """Assert each unoccluded joint's label blob is centred on Camera.project; returns how many were checked."""
    labels = render_joint_labels(points, cam.K, cam.cam_from_world, cam.image_size, joint_radius_m=radius_m)
    assert labels.shape == (cam.image_size[1], cam.image_size[0])
    px, depth = cam.project(points)
    checked = 0
    for j in range(len(points)):
        ys, xs = np.nonzero(labels == j)
        r_px = np.sqrt(cam.K[0, 0] * cam.K[1, 1]) * radius_m / depth[j]
        if len(xs) < 0.8 * np.pi * r_px**2:  # (partly) hidden behind a nearer joint: centroid biased
            continue
        centroid = np.array([xs.mean(), ys.mean()]) + 0.5  # pixel centres; our pixel origin is the corner
        assert np.linalg.norm(centroid - px[j]) < 2.0, (j, centroid, px[j])
        checked += 1
    return checked


def test_rendered_joints_sit_at_rig_camera_projections(gl, tiny_sample):
    """From each rig camera's exact K and pose, every visible joint sphere is centred on Camera.project."""
    for v in range(tiny_sample.n_cameras):
        n = int(np.flatnonzero(tiny_sample.cam_id == v)[0])
        cam = Camera(tiny_sample.K[n], tiny_sample.cam_from_world[n], tuple(tiny_sample.image_size[v]))
        checked = _check_label_centroids(tiny_sample.points3d[n], cam, radius_m=0.01)
        assert checked >= 0.6 * tiny_sample.n_joints


def test_rendered_joints_sit_at_projections_of_an_asymmetric_camera(gl, tiny_sample):
    """Projection conventions survive an asymmetric camera.

    ``fx != fy``, off-centre principal point, non-square image and a rolled camera: a transposed or
    flipped convention would move blobs by tens of pixels.
    """
    K = np.array([[900.0, 0.0, 430.0], [0.0, 1150.0, 250.0], [0.0, 0.0, 1.0]])
    T = look_at(np.array([2.2, -1.6, 1.9]), np.array([0.1, 0.2, 0.9]))
    roll = np.eye(4)
    roll[:2, :2] = [[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]]
    cam = Camera(K, roll @ T, image_size=(800, 560))
    points = tiny_sample.points3d[3] - tiny_sample.points3d[3].mean(axis=0) + (0.1, 0.2, 0.9)
    assert _check_label_centroids(points, cam, radius_m=0.012) >= 0.6 * len(points)


def test_render_view_colours_sides(gl, tiny_sample):
    """Flat render: not blank, and left/right joints show their side colours at their projections."""
    n, v = 0, int(tiny_sample.cam_id[0])
    size = tuple(tiny_sample.image_size[v])
    img = render_view(
        tiny_sample.points3d[n], tiny_sample.skeleton, tiny_sample.K[n], tiny_sample.cam_from_world[n], size,
        scale=0.5, flat=True, joint_radius_m=0.03,
    )  # fmt: skip
    assert img.shape == (size[1] // 2, size[0] // 2, 3) and img.dtype == np.uint8
    assert img.std() > 5.0
    px = tiny_sample.keypoints_gt_px[n] * 0.5
    sides = joint_sides(tiny_sample.skeleton)
    palette = np.array(SIDE_RGB) * 255
    hits = total = 0
    for j in np.flatnonzero(sides != CENTRE):
        c = img[int(px[j, 1]), int(px[j, 0])].astype(float)
        total += 1
        hits += int(
            np.argmin(np.linalg.norm(palette - c, axis=1)) == sides[j]
            and np.abs(c - palette[sides[j]]).max() < 40
        )
    assert hits >= 0.7 * total


def test_opengl_camera_pose_flips_y_and_z():
    T = look_at(np.array([0.0, -4.0, 1.5]), np.array([0.0, 0.0, 1.5]))
    pose = opengl_camera_pose(T)
    assert np.allclose(pose[:3, 3], [0.0, -4.0, 1.5])
    assert np.allclose(-pose[:3, 2], [0.0, 1.0, 0.0])  # GL looks along -z: towards the target
    assert np.allclose(pose[:3, 1], [0.0, 0.0, 1.0])  # GL y up = world up for an upright camera


def test_no_backend_gives_one_clear_error(monkeypatch):
    def broken(platform, *, retry):
        raise ImportError(f"cannot load lib{platform}")

    monkeypatch.setattr(_gl, "_STATE", {})
    monkeypatch.setattr(_gl, "_try_backend", broken)
    monkeypatch.delenv("PYOPENGL_PLATFORM", raising=False)
    with pytest.raises(
        _gl.RendererUnavailableError, match=r"egl: cannot load libegl; osmesa: cannot load libosmesa"
    ):
        _gl.offscreen_renderer(64, 64)
    with pytest.raises(_gl.RendererUnavailableError):  # the failure is remembered, not retried
        _gl.offscreen_renderer(64, 64)


def test_joint_sides_from_names_and_mirror():
    sk = cmu31()
    sides = joint_sides(sk)
    assert sides[sk.index("lfemur")] == LEFT and sides[sk.index("rfemur")] == RIGHT
    assert sides[sk.index("head")] == CENTRE and sides[sk.index("LeftHand")] == LEFT
    two = Skeleton(
        "pair", ("a_lknee", "a_rknee", "b_lknee", "b_rknee"), (-1, -1, -1, -1), mirror=(1, 0, 3, 2)
    )
    assert joint_sides(two).tolist() == [LEFT, RIGHT, LEFT, RIGHT]
    assert all(0.0 <= c <= 1.0 for rgb in SIDE_RGB for c in rgb)


@pytest.mark.parametrize("width_px", [None, 640])
def test_overlay_marks_observations_and_missing_joints(tiny_sample, width_px):
    """Pixels at isolated joints: an observed joint's disc has its side colour, a missing one the magenta cross."""
    n = int(np.argmax((~tiny_sample.visible).sum(axis=1)))  # an image with missing joints
    w_img = float(tiny_sample.image_size[tiny_sample.cam_id[n], 0])
    s = 1.0 if width_px is None else width_px / w_img
    img = draw_overlay(tiny_sample, n, width_px=width_px, text=False)
    sides = joint_sides(tiny_sample.skeleton)
    obs = tiny_sample.keypoints_px[n].astype(np.float64) * s
    gt = tiny_sample.keypoints_gt_px[n].astype(np.float64) * s
    markers = np.concatenate([np.where(np.isnan(obs), gt, obs)[:, None], gt[:, None]], axis=1)  # (J, 2, 2)
    inside = (gt[:, 0] >= 0) & (gt[:, 0] < img.shape[1]) & (gt[:, 1] >= 0) & (gt[:, 1] < img.shape[0])
    seen = missing = 0
    for j in range(tiny_sample.n_joints):
        others = np.delete(markers, j, axis=0).reshape(-1, 2)
        if (
            not inside[j] or np.linalg.norm(others - gt[j], axis=1).min() < 16
        ):  # another marker may overdraw it
            continue
        if tiny_sample.visible[n, j]:
            assert tuple(img[int(obs[j, 1]), int(obs[j, 0])]) == side_bgr_u8(sides[j]), j
            seen += 1
        else:
            assert tuple(img[int(gt[j, 1]), int(gt[j, 0])]) == MISSING_BGR, j
            missing += 1
    assert seen >= 4 and missing >= 1, (seen, missing)


def test_overlay_rejects_bad_index(tiny_sample):
    with pytest.raises(IndexError, match="out of range"):
        draw_overlay(tiny_sample, tiny_sample.n_images)


def test_contact_sheet_rows_are_cameras_and_columns_are_time(tiny_sample):
    """Stored in a shuffled order, the columns still follow the timestamps and each tile sits in its camera's row."""
    sample = _shuffled(tiny_sample)
    tw, th = 60, 80
    sheet = contact_sheet(sample, tile_px=(tw, th), max_images=10)
    cols = sheet_columns(sample, 10)
    assert sheet.shape == (72 + sample.n_cameras * th, 64 + 10 * tw, 3)
    assert np.all(np.diff(sample.timestamp_s[cols]) > 0)
    assert np.allclose(sample.timestamp_s[cols], np.sort(tiny_sample.timestamp_s)[:10])
    for k, n in enumerate(cols):
        for v in range(sample.n_cameras):
            tile = sheet[72 + v * th : 72 + (v + 1) * th, 64 + k * tw : 64 + (k + 1) * tw - 1]
            assert (tile != 8).any() == (v == sample.cam_id[n]), (k, v)


def test_write_video_has_one_frame_per_image(tiny_sample, tmp_path):
    path = write_video(tiny_sample, tmp_path / "s.mp4", panel_px=120)
    cap = cv2.VideoCapture(str(path))
    frames = 0
    while cap.read()[0]:
        frames += 1
    cap.release()
    assert frames == tiny_sample.n_images


def test_render_samples_writes_2d_without_gl(tiny_sample, tmp_path):
    pytest.importorskip("matplotlib")
    paths = render_samples([tiny_sample], tmp_path, progress=False, render_3d=False, sheet_images=24)
    names = ["train-000000_contact.png", "train-000000_contact_p2.png", "train-000000_timestamps.png"]
    assert [p.name for p in paths] == names
    assert all(cv2.imread(str(p)) is not None for p in paths)


def test_contact_sheet_pages_cap_the_width_and_cover_every_image(tiny_sample):
    """48 images of 120 px no longer make one 5,824 px strip: pages of at most 16 columns, in time order."""
    pages = contact_sheets(tiny_sample, max_images=None)
    per_page = (MAX_SHEET_WIDTH_PX - 64) // 120
    assert len(pages) == -(-tiny_sample.n_images // per_page) >= 2
    assert all(p.shape[1] <= MAX_SHEET_WIDTH_PX for p in pages)
    assert sum((p.shape[1] - 64) // 120 for p in pages) == tiny_sample.n_images
    one = contact_sheet(tiny_sample, max_images=None, max_width_px=None)
    assert one.shape[1] == 64 + 120 * tiny_sample.n_images
    with pytest.raises(IndexError, match="page"):
        contact_sheet(tiny_sample, max_images=None, page=len(pages))


def test_two_subjects_get_distinct_colours_and_separate_motion_names():
    from gttdata.capture.simulate import merge_subjects
    from gttdata.mocap.procedural import generate_motion

    a, b = generate_motion("walk", seed=1, duration_s=1.0), generate_motion("jog", seed=2, duration_s=1.0)
    sk = merge_subjects([a, b], np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])).skeleton
    subj = joint_subjects(sk)
    assert subj.tolist() == [0] * a.skeleton.n_joints + [1] * a.skeleton.n_joints
    rgb = joint_rgb(sk)
    assert not {tuple(c) for c in rgb[subj == 0]} & {tuple(c) for c in rgb[subj == 1]}
    assert not joint_subjects(a.skeleton).any()
    assert np.allclose(joint_rgb(a.skeleton), np.array(SIDE_RGB)[joint_sides(a.skeleton)])

    class _S:
        meta = {
            "n_subjects": 2,
            "motions": [{"name": "x/walk", "subject": 0}, {"name": "y/jog", "subject": 1}],
        }
        motion_name = "x/walk|y/jog"

    assert motion_label(_S()) == "a: x/walk, b: y/jog"


def test_front_azimuth_follows_the_facing_direction():
    """A skeleton whose left side points to +y faces +x (left x z); turned 90 degrees it faces +y."""
    sk = cmu31()
    sides = joint_sides(sk)
    p = np.zeros((sk.n_joints, 3))
    p[sides == LEFT, 1], p[sides == RIGHT, 1] = 0.2, -0.2
    assert front_azimuth_deg(p, sk) == pytest.approx(0.0, abs=1e-9)
    turned = p @ np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # +90 deg about z
    assert front_azimuth_deg(turned, sk) == pytest.approx(90.0, abs=1e-9)


def test_plot_dataset_writes_nonempty_pngs(tiny_dataset, tmp_path):
    pytest.importorskip("matplotlib")
    from gttdata.preview.plots import collect_statistics, open_source, plot_dataset

    paths = plot_dataset(tiny_dataset, tmp_path, split="train")
    names = ["timestamp_raster", "noise_sigma", "missing_rate", "sequence_length", "motion_sources"]
    assert [p.stem for p in paths] == names
    for p in paths:
        img = cv2.imread(str(p))
        assert img is not None and img.shape[0] > 100 and img.std() > 5, p
    stats = collect_statistics(open_source(tiny_dataset, "train"))
    assert stats["n_read"] == 4 and np.allclose(stats["sigma_px"], 1.0)
    assert sum(stats["motions"].values()) == 4 and all(k.startswith("procedural/") for k in stats["motions"])


def test_cli_preview_dataset_dir(tiny_dataset, tmp_path, gl):
    out = tmp_path / "p"
    args = [
        "preview",
        str(tiny_dataset),
        "--split",
        "val",
        "-s",
        "0",
        "-s",
        "1",
        "--out",
        str(out),
        "--video",
    ]
    res = CliRunner().invoke(main, [*args, "--no-progress"])
    assert res.exit_code == 0, res.output
    printed = res.output.split()
    for stem in ("val-000000", "val-000001"):
        for suffix in ("_contact.png", "_3d.png", "_timestamps.png", ".mp4"):
            assert str(out / f"{stem}{suffix}") in printed
    assert str(out / "motion_sources.png") in printed
    assert all((out / p).stat().st_size > 1000 for p in printed)


@pytest.mark.parametrize(
    ("extra", "exit_code", "expected"),
    [
        (["--no-3d", "--no-plots"], 0, "train-000001_contact.png"),
        (["--sample", "99"], 1, "out of range"),
        (["--variant", "nope"], 1, "no variant 'nope'"),
    ],
)
def test_cli_preview_shard(tiny_dataset, tmp_path, extra, exit_code, expected):
    shard = tiny_dataset / "train" / "shard-00000.h5"
    res = CliRunner().invoke(
        main, ["preview", str(shard), "-s", "1", "--out", str(tmp_path), "--no-progress", *extra]
    )
    assert res.exit_code == exit_code, res.output
    assert expected in res.output
    if exit_code == 0:
        assert "_3d.png" not in res.output and "timestamp_raster" not in res.output


def test_timestamp_raster_adds_zoom_panel_for_dense_captures(tiny_sample, tmp_path):
    pytest.importorskip("matplotlib")
    from gttdata.preview.plots import plot_timestamp_raster

    plain = cv2.imread(str(plot_timestamp_raster(tiny_sample, tmp_path / "a.png")))
    zoomed = cv2.imread(str(plot_timestamp_raster(tiny_sample, tmp_path / "b.png", zoom_above=10)))
    assert plain.shape[1] == zoomed.shape[1] and zoomed.shape[0] > 1.5 * plain.shape[0]
