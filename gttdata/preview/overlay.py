"""2-D previews drawn with OpenCV: per-image keypoint overlays, the cameras-by-time contact sheet and an MP4."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from gttdata.capture.sample import CaptureSample
from gttdata.preview._style import (
    CENTRE,
    LEFT,
    RIGHT,
    SUBJECT_RGB,
    bone_rgb,
    joint_rgb,
    joint_subjects,
    rgb_bgr_u8,
    side_bgr_u8,
)

__all__ = [
    "BACKGROUND_BGR",
    "MISSING_BGR",
    "MAX_SHEET_WIDTH_PX",
    "contact_sheet",
    "contact_sheets",
    "crop_windows",
    "motion_label",
    "draw_overlay",
    "sheet_columns",
    "write_video",
]

#: Canvas colour (BGR) outside and inside the camera image.
BACKGROUND_BGR = (18, 18, 18)
_IMAGE_BGR = (40, 38, 36)
#: Cross drawn at the ground-truth projection of a missing joint (BGR magenta).
MISSING_BGR = (255, 0, 255)
_GT_BGR = (255, 255, 255)
_ERROR_BGR = (150, 150, 150)
#: Widest contact sheet page, pixels: 16 columns of the default 120 px tiles; more images go on more pages.
MAX_SHEET_WIDTH_PX = 2048
_SHIFT = 4  # OpenCV fixed-point drawing: coordinates carry 4 fractional bits, so markers sit sub-pixel exact.
_ONE = 1 << _SHIFT


def _fx(u: float, v: float) -> tuple[int, int]:
    return int(round(u * _ONE)), int(round(v * _ONE))


def crop_windows(
    sample: CaptureSample,
    *,
    aspect: float = 1.0,
    margin: float = 0.1,
    images: np.ndarray | None = None,
) -> np.ndarray:
    """Per camera, a window around every ground-truth projection of that camera, so the subject fills a tile.

    One window per camera (not per image), so the subject's motion across the image stays visible.

    Args:
        sample: The capture.
        aspect: Width / height of the windows.
        margin: Padding added on each side, as a fraction of the box size.
        images: Consider only these image indices, shape ``(M,)`` (default: all).

    Returns:
        ``(x0, y0, x1, y1)`` per camera in camera pixels, shape ``(V, 4)`` float64; the full image for a
        camera without any finite projection inside its image.
    """
    out = np.zeros((sample.n_cameras, 4))
    for v in range(sample.n_cameras):
        w, h = (float(x) for x in sample.image_size[v])
        sel = sample.cam_id == v
        if images is not None:
            sel &= np.isin(np.arange(sample.n_images), images)
        pts = sample.keypoints_gt_px[sel].reshape(-1, 2).astype(np.float64)
        pts = pts[np.isfinite(pts).all(axis=1)]
        pts = pts[(pts[:, 0] >= 0) & (pts[:, 0] < w) & (pts[:, 1] >= 0) & (pts[:, 1] < h)]
        if not len(pts):
            out[v] = (0.0, 0.0, w, h)
            continue
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        c = (lo + hi) / 2
        size = (hi - lo) * (1 + 2 * margin) + 20.0
        bw, bh = max(size[0], size[1] * aspect), max(size[1], size[0] / aspect)
        # Slide the window back inside the image where it fits, rather than show empty canvas.
        c = np.clip(
            c,
            np.minimum([bw / 2, bh / 2], [w / 2, h / 2]),
            np.maximum([w - bw / 2, h - bh / 2], [w / 2, h / 2]),
        )
        out[v] = (c[0] - bw / 2, c[1] - bh / 2, c[0] + bw / 2, c[1] + bh / 2)
    return out


def draw_overlay(
    sample: CaptureSample,
    n: int,
    *,
    window: tuple[float, float, float, float] | np.ndarray | None = None,
    width_px: int | None = None,
    text: bool = True,
) -> np.ndarray:
    """Draw image ``n``'s 2-D data on a blank canvas.

    Bones join the ground-truth projections (darker shade of the joint colour); each observed joint is a
    filled disc in its colour (one subject: left blue, right orange-red, midline grey; several subjects:
    one hue per subject, lighter left and darker right, see ``_style.joint_rgb``) with a white ring at its ground-truth
    projection and a grey line to it when the detection error is visible (outputs at least 240 px wide);
    a missing joint is a magenta cross at its ground-truth projection. The camera image is the lighter
    rectangle.

    Args:
        sample: The capture.
        n: Image index in ``[0, N)``.
        window: ``(x0, y0, x1, y1)`` region of the camera image to show, pixels (default: whole image).
        width_px: Output width; the height keeps the window's aspect (default: the window's width).
        text: Write camera id, timestamp and stream index in the top-left corner.

    Returns:
        BGR image uint8. Camera pixel ``(u, v)`` maps to ``((u - x0) * s, (v - y0) * s)`` with
        ``s = width_px / (x1 - x0)``.
    """
    if not 0 <= n < sample.n_images:
        raise IndexError(f"sample {sample.name!r}: image {n} out of range for {sample.n_images} images")
    v = int(sample.cam_id[n])
    w_img, h_img = (float(x) for x in sample.image_size[v])
    x0, y0, x1, y1 = (0.0, 0.0, w_img, h_img) if window is None else (float(x) for x in window)
    out_w = int(round(x1 - x0)) if width_px is None else int(width_px)
    s = out_w / (x1 - x0)
    out_h = max(1, int(round((y1 - y0) * s)))
    img = np.empty((out_h, out_w, 3), np.uint8)
    img[:] = BACKGROUND_BGR
    cv2.rectangle(
        img,
        _fx(-x0 * s, -y0 * s),
        _fx((w_img - x0) * s, (h_img - y0) * s),
        _IMAGE_BGR,
        -1,
        cv2.LINE_8,
        _SHIFT,
    )

    r = float(np.clip(out_w / 80.0, 1.5, 6.0))
    thick = max(1, int(round(r / 2)))
    rings = out_w >= 240  # ground-truth rings and error lines only where they do not clutter small tiles
    gt = (sample.keypoints_gt_px[n].astype(np.float64) - (x0, y0)) * s
    obs = (sample.keypoints_px[n].astype(np.float64) - (x0, y0)) * s
    vis = sample.visible[n] & np.isfinite(obs).all(axis=1)
    ok_gt = np.isfinite(gt).all(axis=1)
    colours = [rgb_bgr_u8(c) for c in joint_rgb(sample.skeleton)]
    for (a, b), rgb in zip(sample.skeleton.limbs, bone_rgb(sample.skeleton), strict=True):
        if ok_gt[a] and ok_gt[b]:
            colour = tuple(int(c * 0.6) for c in rgb_bgr_u8(rgb))
            cv2.line(img, _fx(*gt[a]), _fx(*gt[b]), colour, thick, cv2.LINE_AA, _SHIFT)
    for j in np.flatnonzero(vis & ok_gt & rings):
        if np.linalg.norm(obs[j] - gt[j]) > r:
            cv2.line(img, _fx(*gt[j]), _fx(*obs[j]), _ERROR_BGR, 1, cv2.LINE_AA, _SHIFT)
        cv2.circle(img, _fx(*gt[j]), int(round((r + 2) * _ONE)), _GT_BGR, 1, cv2.LINE_AA, _SHIFT)
    for j in np.flatnonzero(vis):
        cv2.circle(img, _fx(*obs[j]), int(round(r * _ONE)), colours[j], -1, cv2.LINE_8, _SHIFT)
    c = r + 1
    for j in np.flatnonzero(~vis & ok_gt):
        u, vv = gt[j]
        cv2.line(img, _fx(u - c, vv - c), _fx(u + c, vv + c), MISSING_BGR, thick, cv2.LINE_8, _SHIFT)
        cv2.line(img, _fx(u - c, vv + c), _fx(u + c, vv - c), MISSING_BGR, thick, cv2.LINE_8, _SHIFT)
    if text:
        font = float(np.clip(out_w / 500.0, 0.3, 0.7))
        label = f"cam {v}  t={sample.timestamp_s[n]:.3f}s  #{int(sample.stream_index[n])}"
        y = int(round(16 * font / 0.45))
        cv2.putText(img, label, (4, y), cv2.FONT_HERSHEY_SIMPLEX, font, (230, 230, 230), 1, cv2.LINE_AA)
    return img


def sheet_columns(sample: CaptureSample, max_images: int | None = None) -> np.ndarray:
    """Images shown by :func:`contact_sheet`, in the order of its columns (true time order).

    Args:
        sample: The capture.
        max_images: Keep only the first ``max_images`` images in time (None: all).

    Returns:
        Image indices, column by column, shape ``(C,)`` int64.
    """
    order = np.argsort(sample.timestamp_s, kind="stable")
    return order if max_images is None else order[:max_images]


def motion_label(sample: CaptureSample) -> str:
    """The sample's motion(s) for a title: one name, or ``a: <name>, b: <name>`` per subject/event."""
    records = sample.meta.get("motions") or []
    if len(records) > 1:
        subjects = [r.get("subject") for r in records]
        if sample.meta.get("n_subjects", 1) > 1 and all(isinstance(x, int) for x in subjects):
            return ", ".join(
                f"{chr(ord('a') + x)}: {r.get('name', '?')}" for x, r in zip(subjects, records, strict=True)
            )
        return ", ".join(f"event {k + 1}: {r.get('name', '?')}" for k, r in enumerate(records))
    names = [n for n in str(sample.motion_name).split("|") if n]
    return ", ".join(names)


def _sheet_per_page(tile_w: int, max_width_px: int | None) -> int | None:
    return None if max_width_px is None else max(1, (int(max_width_px) - 64) // int(tile_w))


def contact_sheet(
    sample: CaptureSample,
    *,
    tile_px: tuple[int, int] = (120, 160),
    max_images: int | None = 48,
    crop: bool = True,
    page: int = 0,
    max_width_px: int | None = MAX_SHEET_WIDTH_PX,
) -> np.ndarray:
    """Cameras-by-time grid of 2-D overlays: row v holds camera v's images, column k the k-th image in time.

    Each column holds exactly one image, so the interleaving of the unsynchronized cameras shows as a
    staircase; each column is headed by its timestamp in milliseconds. The columns are cut into pages no
    wider than ``max_width_px`` (:func:`contact_sheets` returns them all); this draws page ``page``.

    Args:
        sample: The capture.
        tile_px: Tile ``(width, height)``, pixels.
        max_images: Show the first ``max_images`` images in time (None: all).
        crop: Zoom every camera onto the subject (:func:`crop_windows`) instead of the whole image.
        page: Page index, from 0.
        max_width_px: Widest page, pixels (None: one page however wide).

    Returns:
        BGR image uint8 of shape ``(72 + V * th, 64 + C * tw, 3)`` for ``tile_px = (tw, th)`` and the C
        columns of this page (a slice of :func:`sheet_columns`); the tile of column k of the page, camera v
        starts at ``(x, y) = (64 + k * tw, 72 + v * th)``.
    """
    all_cols = sheet_columns(sample, max_images)
    V = sample.n_cameras
    tw, th = (int(x) for x in tile_px)
    per_page = _sheet_per_page(tw, max_width_px) or max(1, len(all_cols))
    n_pages = max(1, -(-len(all_cols) // per_page))
    if not 0 <= page < n_pages:
        raise IndexError(
            f"sample {sample.name!r}: contact sheet page {page} out of range for {n_pages} pages"
        )
    first = page * per_page
    cols = all_cols[first : first + per_page]
    left, top = 64, 72
    sheet = np.zeros((top + V * th, left + len(cols) * tw, 3), np.uint8)
    sheet[:] = (8, 8, 8)
    windows = crop_windows(sample, aspect=tw / th, images=all_cols) if crop else None
    font = cv2.FONT_HERSHEY_SIMPLEX
    if len(cols) < sample.n_images:
        shown = f"images {first + 1}-{first + len(cols)} of {sample.n_images}"
    else:
        shown = f"{sample.n_images} images"
    pages = f", page {page + 1}/{n_pages}" if n_pages > 1 else ""
    title = (
        f"{sample.name} [{sample.variant}]  {motion_label(sample)}  {V} cameras, {shown}{pages}; "
        f"columns in time order (ms){', zoomed on the subject' if crop else ''}"
    )
    cv2.putText(sheet, title, (6, 20), font, 0.5, (235, 235, 235), 1, cv2.LINE_AA)
    subjects = joint_subjects(sample.skeleton)
    if subjects.any():
        legend = [("observed joints:", (200, 200, 200))]
        legend += [
            (f"subject {chr(ord('a') + s)}", rgb_bgr_u8(SUBJECT_RGB[s % len(SUBJECT_RGB)][LEFT]))
            for s in np.unique(subjects)
        ]
        legend += [("(lighter: left, darker: right)", (200, 200, 200))]
    else:
        legend = [
            ("observed joints:", (200, 200, 200)),
            ("left", side_bgr_u8(LEFT)),
            ("right", side_bgr_u8(RIGHT)),
            ("midline", side_bgr_u8(CENTRE)),
        ]
    x = 6
    for text, colour in [*legend, ("missing joint: x at its true position", MISSING_BGR)]:
        cv2.putText(sheet, text, (x, 42), font, 0.45, colour, 1, cv2.LINE_AA)
        x += cv2.getTextSize(text, font, 0.45, 1)[0][0] + 10
    for v in range(V):
        y = top + v * th + th // 2
        cv2.putText(sheet, f"cam {v}", (6, y), font, 0.45, (235, 235, 235), 1, cv2.LINE_AA)
    for k, n in enumerate(cols):
        v = int(sample.cam_id[n])
        x, y = left + k * tw, top + v * th
        win = None if windows is None else windows[v]
        tile = draw_overlay(sample, int(n), window=win, width_px=tw, text=False)
        h = min(tile.shape[0], th)
        sheet[y : y + h, x : x + tw - 1] = tile[:h, : tw - 1]
        cv2.putText(
            sheet, f"{sample.timestamp_s[n] * 1000:.0f}", (x + 4, top - 8), font, 0.4, (200, 200, 200), 1
        )
    return sheet


def contact_sheets(
    sample: CaptureSample,
    *,
    tile_px: tuple[int, int] = (120, 160),
    max_images: int | None = 48,
    crop: bool = True,
    max_width_px: int | None = MAX_SHEET_WIDTH_PX,
) -> list[np.ndarray]:
    """Every page of :func:`contact_sheet` (same arguments), in order; the first page first."""
    n_cols = len(sheet_columns(sample, max_images))
    per_page = _sheet_per_page(int(tile_px[0]), max_width_px) or max(1, n_cols)
    n_pages = max(1, -(-n_cols // per_page))
    return [
        contact_sheet(
            sample, tile_px=tile_px, max_images=max_images, crop=crop, page=p, max_width_px=max_width_px
        )
        for p in range(n_pages)
    ]


def write_video(
    sample: CaptureSample, path: str | Path, *, fps: float = 6.0, panel_px: int = 320, crop: bool = True
) -> Path:
    """MP4 (``mp4v``) of the sample in global time order: one frame per image.

    Each frame shows one panel per camera holding that camera's latest image so far; the panel of the
    image just taken has a yellow border, so the cameras visibly fire one after another.

    Args:
        sample: The capture.
        path: Output ``.mp4`` file.
        fps: Playback frames (images) per second.
        panel_px: Panel width and height, pixels.
        crop: Zoom each camera onto the subject (:func:`crop_windows`).

    Returns:
        ``path``.

    Raises:
        OSError: OpenCV cannot open a writer for ``path``.
    """
    path = Path(path)
    V = sample.n_cameras
    panel_px += panel_px % 2
    size = (V * panel_px, panel_px + 32)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"mp4v"), float(fps), size)
    if not writer.isOpened():
        raise OSError(f"{path}: OpenCV cannot write an mp4v video here")
    windows = crop_windows(sample) if crop else [None] * V
    panels = [np.full((panel_px, panel_px, 3), BACKGROUND_BGR, np.uint8) for _ in range(V)]
    order = sheet_columns(sample)
    try:
        for k, n in enumerate(order):
            v = int(sample.cam_id[n])
            tile = draw_overlay(sample, int(n), window=windows[v], width_px=panel_px)
            panels[v] = np.zeros((panel_px, panel_px, 3), np.uint8)
            panels[v][: min(panel_px, tile.shape[0])] = tile[:panel_px]
            frame = np.zeros((size[1], size[0], 3), np.uint8)
            frame[32:] = np.concatenate(panels, axis=1)
            cv2.rectangle(frame, (v * panel_px, 32), ((v + 1) * panel_px - 1, size[1] - 1), (0, 230, 255), 3)
            label = f"{sample.name}  t={sample.timestamp_s[n]:.3f}s  image {k + 1}/{len(order)}  cam {v}"
            cv2.putText(
                frame, label, (6, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (235, 235, 235), 1, cv2.LINE_AA
            )
            writer.write(frame)
    finally:
        writer.release()
    return path
