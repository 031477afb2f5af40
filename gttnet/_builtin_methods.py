"""The built-in reconstruction methods by name, standard library only (``--help`` lists them without numpy)."""

from __future__ import annotations

__all__ = ["BUILTIN_METHODS"]

#: Each built-in method and the module whose ``@register_method`` defines it. A lookup by name imports that
#: module only: ``gttnet`` (torch) costs about a second of start-up that ``dloe`` or ``sync`` never needs.
#: ``tests/gttnet/test_baselines.py`` checks this table against what the modules register.
BUILTIN_METHODS: dict[str, str] = {
    "auto": "gttnet.auto",
    "dct": "gttnet.baselines.trajectory_basis",
    "dloe": "gttnet.baselines.dloe",
    "gttnet": "gttnet.model.inference",
    "hpf": "gttnet.baselines.highpass",
    "pseudo": "gttnet.baselines.pseudo",
    "stream-sync": "gttnet.sync.method",
    "sync": "gttnet.sync.method",
}
