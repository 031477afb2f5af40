"""Environment for tests that run the project in a child process."""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def repo_env() -> dict[str, str]:
    """``os.environ`` with this checkout first on ``PYTHONPATH``, so a child process imports the code under test."""
    return {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")])),
    }
