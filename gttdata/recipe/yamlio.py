"""YAML for recipes: PyYAML's safe loader, with YAML 1.2 number syntax.

PyYAML follows YAML 1.1, where ``5e-1`` and ``1e12`` (no dot) are strings, so a recipe value written as
``sigma: 5e-1`` was refused as text. YAML 1.2 (and every other tool a user knows) reads them as numbers.
"""

from __future__ import annotations

import re

import yaml

__all__ = ["RecipeYamlLoader", "load_yaml"]


class RecipeYamlLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads ``5e-1``, ``1e12`` and ``-2E+3`` as floats."""


RecipeYamlLoader.yaml_implicit_resolvers = {
    key: list(value) for key, value in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
RecipeYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_yaml(text: str) -> object:
    """Parse YAML text safely, with YAML 1.2 exponent numbers."""
    return yaml.load(text, Loader=RecipeYamlLoader)  # noqa: S506 - a SafeLoader subclass
