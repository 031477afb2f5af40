"""Mutations of valid input files for the reader fuzz tests and the audit replay.

A document (parsed JSON, TOML or YAML: dicts, lists and scalars) is mutated at one place: a value is
replaced by a value of another type or an absurd number, a key is deleted, a list is emptied or nested
one level deeper. Text files (CSV, OpenCV YAML) are mutated cell by cell or line by line.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterator

from hypothesis import strategies as st

__all__ = ["BAD_VALUES", "apply", "doc_mutations", "paths", "text_mutations"]

#: Replacement values: wrong types, non-finite and absurd numbers, negative counts, empty containers.
BAD_VALUES: tuple[object, ...] = (
    None,
    "abc",
    "1.5",
    "",
    True,
    0,
    -1,
    -5000.0,
    1e300,
    -1e300,
    math.nan,
    math.inf,
    -math.inf,
    [],
    {},
    [[1.0]],
    {"a": 1},
    [None],
    ["x", "y"],
)

#: Operations besides replacement.
OPS: tuple[str, ...] = ("delete", "empty", "nest", "duplicate")


def paths(doc: object, prefix: tuple = ()) -> Iterator[tuple]:
    """Every path (a tuple of keys and indices) into ``doc``, the root ``()`` included."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:4]):  # the first few elements are enough to reach every field
            yield from paths(v, (*prefix, i))


def apply(doc: object, path: tuple, op: object) -> object:
    """A copy of ``doc`` with the node at ``path`` replaced by ``op`` (a value) or changed by a name of :data:`OPS`."""
    doc = copy.deepcopy(doc)
    if not path:
        return _changed(doc, op)
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    last = path[-1]
    if op == "delete":
        del parent[last]
    elif op == "duplicate" and isinstance(parent, list):
        parent.insert(last, copy.deepcopy(parent[last]))
    else:
        parent[last] = _changed(parent[last], op)
    return doc


def _changed(node: object, op: object) -> object:
    if op == "empty":
        return type(node)() if isinstance(node, dict | list | str) else None
    if op == "nest":
        return [node]
    if op in ("delete", "duplicate"):
        return None
    return copy.deepcopy(op)


def doc_mutations(doc: object, values: tuple = BAD_VALUES) -> st.SearchStrategy:
    """Hypothesis strategy of ``(path, op)`` pairs for :func:`apply` on ``doc``."""
    all_paths = list(paths(doc))
    ops = st.sampled_from(list(values) + list(OPS))
    return st.tuples(st.sampled_from(all_paths), ops)


def text_mutations(text: str) -> st.SearchStrategy:
    """Hypothesis strategy of mutated copies of a line-oriented text (CSV, YAML): one line or cell changed."""
    lines = text.splitlines()

    @st.composite
    def mutate(draw) -> str:
        out = list(lines)
        k = draw(st.integers(0, len(out) - 1))
        op = draw(st.sampled_from(["drop", "dup", "cell", "garbage", "truncate", "cut"]))
        if op == "drop":
            del out[k]
        elif op == "dup":
            out.insert(k, out[k])
        elif op == "garbage":
            out[k] = draw(
                st.sampled_from(["", ",,,", "nan", "\x00\xff", "a,b", "1e999,inf,-inf", "[", "{x: }"])
            )
        elif op == "truncate":
            out = out[:k]
        elif op == "cut":
            out[k] = out[k][: draw(st.integers(0, max(len(out[k]) - 1, 0)))]
        else:
            cells = out[k].split(",")
            i = draw(st.integers(0, len(cells) - 1))
            cells[i] = draw(
                st.sampled_from(["", "abc", "nan", "inf", "-1e300", "1e300", "-5000", "0", "-1", "1.5.2"])
            )
            out[k] = ",".join(cells)
        return "\n".join(out) + "\n"

    return mutate()
