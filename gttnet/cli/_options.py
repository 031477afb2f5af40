"""Option values shared by the gttnet commands (docs/CLI.md), kept free of heavy imports for a fast --help."""

from __future__ import annotations

__all__ = ["AFFINITY_METHODS", "SPLIT_DEFAULT"]

#: The registered methods that return an affinity between images (segmentation, two subjects), spelled out
#: so that ``--help`` needs no torch; tests/test_cli_convention.py checks they are registered.
AFFINITY_METHODS: tuple[str, ...] = ("dloe", "gttnet", "pseudo")

#: Default ``--split`` of every command that reads a dataset folder.
SPLIT_DEFAULT = "test"
