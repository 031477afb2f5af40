"""Option values shared by the gttnet commands (docs/CLI.md), kept free of heavy imports for a fast --help."""

from __future__ import annotations

from gttdata._cli_common import SPLIT_DEFAULT

__all__ = ["AFFINITY_METHODS", "INPUT_FORMATS", "SPLIT_DEFAULT", "STORED_SAMPLE_HELP", "STORED_SPLIT_HELP"]

#: The registered methods that return an affinity between images (segmentation, two subjects), spelled out
#: so that ``--help`` needs no torch; tests/test_cli_convention.py checks they are registered.
AFFINITY_METHODS: tuple[str, ...] = ("dloe", "gttnet", "pseudo")

#: ``--format`` choices of the commands that read one capture file: ``auto`` and the keys of
#: :data:`gttnet.io.FORMATS`, spelled out so that ``--help`` needs no importer; tests/test_cli_convention.py
#: checks they agree.
INPUT_FORMATS: tuple[str, ...] = ("auto", "h5", "dloe-mat", "gttnet-json")

#: ``--sample``/``--split`` help of the commands that read one stored capture (shard file or dataset folder).
STORED_SAMPLE_HELP = "Sample index in a shard file, or in --split of a dataset directory."
STORED_SPLIT_HELP = "Split of a dataset directory INPUT (a shard file holds one split)."
