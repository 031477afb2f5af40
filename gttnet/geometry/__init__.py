"""Multi-view geometry of unsynchronized images: pseudo-triangulation, neighbourhoods and orderings.

Shape letters used in every docstring of gttnet (defined here once):

* ``B``: batch (sequences, or several affinities of one sequence).
* ``V``: views / cameras.
* ``T``: frames of a motion.
* ``N``: unsynchronised observations (images), each from one camera at its own instant.
* ``J``: joints (the paper's P); ``3J`` is the length of a per-image shape descriptor.
* ``K``: neighbours of an image (the image itself excluded unless stated).
* ``F``: features.

Frames and units follow :mod:`gttdata.cameras`: world z-up in metres, OpenCV camera frames, pixels.
"""

from __future__ import annotations

from gttnet.geometry.neighbours import chain_affinity, neighbourhoods, temporal_chain_affinity
from gttnet.geometry.ordering import graph_components, spectral_order
from gttnet.geometry.triangulation import PseudoTriangulation, closest_points_on_rays, pseudo_triangulate

__all__ = [
    "PseudoTriangulation",
    "chain_affinity",
    "closest_points_on_rays",
    "graph_components",
    "neighbourhoods",
    "pseudo_triangulate",
    "spectral_order",
    "temporal_chain_affinity",
]
