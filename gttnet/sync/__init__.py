"""Clock recovery: per-camera offsets (and drift) of unsynchronized cameras from the skeletons themselves.

``recover_clocks(obs) -> Clocks`` estimates each camera's clock from observations with per-camera frame
order (``partial``); ``apply_clocks(obs, clocks)`` turns them into ``full`` observations that the
timestamp-based solvers accept.
"""

from __future__ import annotations

import logging

from gttnet.sync.clocks import Clocks, apply_clocks, clock_times, local_times, per_camera_rates
from gttnet.sync.recover import recover_clocks

# The warnings (rates, cameras left out) reach users through ``info["time_warnings"]``, which the CLIs print
# by camera name; without a handler here, Python would also print them bare on stderr.
logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = ["Clocks", "apply_clocks", "clock_times", "local_times", "per_camera_rates", "recover_clocks"]
