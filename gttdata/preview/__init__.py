"""Sanity previews of simulated captures: 3-D renders, 2-D overlays, contact sheets, videos and dataset plots."""

from __future__ import annotations

from gttdata.preview._gl import PreviewDependencyError, RendererUnavailableError, gl_backend
from gttdata.preview.overlay import contact_sheet, draw_overlay, write_video
from gttdata.preview.plots import plot_dataset, plot_timestamp_raster
from gttdata.preview.render import render_joint_labels, render_sample_3d, render_samples, render_view

__all__ = [
    "PreviewDependencyError",
    "RendererUnavailableError",
    "contact_sheet",
    "draw_overlay",
    "gl_backend",
    "plot_dataset",
    "plot_timestamp_raster",
    "render_joint_labels",
    "render_sample_3d",
    "render_samples",
    "render_view",
    "write_video",
]
