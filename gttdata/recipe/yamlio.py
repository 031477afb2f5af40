"""YAML for recipes and project files: PyYAML's safe loader, YAML 1.2 number syntax, no duplicate keys.

PyYAML follows YAML 1.1, where ``5e-1`` and ``1e12`` (no dot) are strings, so a recipe value written as
``sigma: 5e-1`` was refused as text. YAML 1.2 (and every other tool a user knows) reads them as numbers.
A key written twice in one mapping (YAML says keys are unique; PyYAML silently keeps the last) is refused
with the key and its line.
"""

from __future__ import annotations

import re

import yaml

__all__ = ["RecipeYamlLoader", "load_yaml", "yaml_error_line"]


class RecipeYamlLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads ``5e-1``, ``1e12`` and ``-2E+3`` as floats and refuses duplicate keys."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        """A mapping; a key that appears twice raises a ``ConstructorError`` marked at its second line."""
        if isinstance(node, yaml.MappingNode):  # a SafeLoader calls this with other nodes too (it then fails)
            seen: dict[object, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.get(key)
                except TypeError:  # an unhashable key: the base class reports it
                    continue
                if first is not None:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"duplicate key {key!r} (first on line {first})", key_node.start_mark
                    )
                seen[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep=deep)


RecipeYamlLoader.yaml_implicit_resolvers = {
    key: list(value) for key, value in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
RecipeYamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)


def load_yaml(text: str) -> object:
    """Parse YAML text safely, with YAML 1.2 exponent numbers, refusing duplicate keys.

    Example:
        >>> load_yaml("a: 5e-1")
        {'a': 0.5}
    """
    try:
        return yaml.load(text, Loader=RecipeYamlLoader)  # noqa: S506 - a SafeLoader subclass
    except RecursionError:
        raise yaml.YAMLError("nested too deeply") from None


def yaml_error_line(exc: yaml.YAMLError) -> str:
    """A PyYAML error in one line: ``line N: problem`` (PyYAML's own message spans several lines)."""
    mark = getattr(exc, "problem_mark", None)
    where = f"line {mark.line + 1}: " if mark is not None else ""
    problem = getattr(exc, "problem", None) or str(exc)
    return where + " ".join(str(problem).split())
