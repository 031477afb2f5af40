"""Applications of the affinity graph: event segmentation and two-subject separation."""

from __future__ import annotations

from gttnet.apps.multi_subject import cluster_subjects, hide_identities, reconstruct_subjects, score_subjects
from gttnet.apps.segment import adjusted_rand_index, score_segmentation, segment_capture, segment_events

__all__ = [
    "adjusted_rand_index",
    "cluster_subjects",
    "hide_identities",
    "reconstruct_subjects",
    "score_segmentation",
    "score_subjects",
    "segment_capture",
    "segment_events",
]
