"""The one YAML-to-dataclass builder of every gtt recipe (generate, train, evaluate), with one-line errors.

Field types may be nested dataclasses (a union of them is told apart by a ``kind`` field), ``list[T]``,
``tuple[T, ...]``, ``dict[str, T]``, ``T | None``, ``Any``, :class:`~gttdata.recipe.param.Param` and the
scalars bool, int, float, str. Field metadata adds checks: ``ge``/``gt``/``le``/``lt`` ranges,
``integer``, ``choices``, ``nonempty``, ``pattern``, ``allow_list`` (Param) and ``path`` (a file the
recipe reads: resolved against the recipe file's folder by :func:`resolve_paths`).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import types
import typing
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import yaml

from gttdata.errors import RecipeError
from gttdata.recipe.param import Param
from gttdata.recipe.yamlio import load_yaml, yaml_error_line

__all__ = [
    "Shorthand",
    "apply_overrides",
    "build_dataclass",
    "read_yaml_mapping",
    "resolve_paths",
    "to_plain",
]

#: Rewrites a raw value before it is converted to a type, e.g. a scalar shorthand for a mapping.
Shorthand = Callable[[object, object], object]

_DIST_KINDS = ("uniform", "choice", "normal")


def _is_number(v: object) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _range_text(meta: dict) -> str:
    parts = [
        f"{op} {meta[k]}" for k, op in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")) if k in meta
    ]
    return " and ".join(parts)


def _in_range(v: float, meta: dict) -> bool:
    return (
        ("ge" not in meta or v >= meta["ge"])
        and ("gt" not in meta or v > meta["gt"])
        and ("le" not in meta or v <= meta["le"])
        and ("lt" not in meta or v < meta["lt"])
    )


def _number_text(meta: dict) -> str:
    word = "an integer" if meta.get("integer") else "a number"
    rng = _range_text(meta)
    return f"{word} {rng}" if rng else word


class _Ctx:
    """Where the values come from (for error messages), the error type raised and the shorthand hook."""

    def __init__(
        self, source: str, error: type[RecipeError] = RecipeError, shorthand: Shorthand | None = None
    ) -> None:
        self.source, self.error, self.shorthand = source, error, shorthand

    def at(self, key: str, text: str) -> RecipeError:
        prefix = f"{self.source}: " if self.source else ""
        return self.error(f"{prefix}{key}: {text}")

    def fail(self, key: str, expected: str, found: object) -> RecipeError:
        return self.at(key, f"expected {expected}, found {found!r}")


def _check_number(ctx: _Ctx, key: str, v: object, meta: dict, expected: str) -> float:
    if not _is_number(v):
        raise ctx.fail(key, expected, v)
    if not math.isfinite(cast(float, v)):
        raise ctx.at(key, f"expected {expected}, found {v!r} (numbers must be finite)")
    x = cast(float, v)  # a finite int or float, not a bool
    if not _in_range(x, meta) or (meta.get("integer") and float(x) != int(x)):
        raise ctx.fail(key, expected, v)
    return int(x) if meta.get("integer") else float(x)


def _convert_param(ctx: _Ctx, key: str, v: object, meta: dict) -> Param:
    num = _number_text(meta)
    expected = f"{num} or a distribution" + (" or a list of them" if meta.get("allow_list") else "")
    kw: dict[str, Any] = {
        "integer": bool(meta.get("integer")),
        "lo": meta.get("ge", meta.get("gt")),
        "hi": meta.get("le", meta.get("lt")),
    }
    if _is_number(v):
        return Param("value", (_check_number(ctx, key, v, meta, expected),), **kw)
    if isinstance(v, list) and meta.get("allow_list"):
        nums = num.replace("a number", "numbers").replace("an integer", "integers")
        if not v:
            raise ctx.fail(key, f"a non-empty list of {nums}", v)
        return Param("list", tuple(_check_number(ctx, key, x, meta, f"a list of {nums}") for x in v), **kw)
    if not (isinstance(v, dict) and len(v) == 1 and next(iter(v)) in _DIST_KINDS):
        raise ctx.fail(key, expected, v)
    kind, args = next(iter(v.items()))
    sub = f"{key}.{kind}"
    if kind == "uniform":
        if (
            not (isinstance(args, list) and len(args) == 2 and all(_is_number(a) for a in args))
            or args[0] > args[1]
        ):
            raise ctx.fail(sub, "[a, b] with a <= b", args)
        args = [_check_number(ctx, sub, a, meta, f"bounds that are each {num}") for a in args]
    elif kind == "choice":
        if not (isinstance(args, list) and args):
            raise ctx.fail(sub, f"a non-empty list of {num}", args)
        args = [_check_number(ctx, sub, a, meta, f"options that are each {num}") for a in args]
    else:
        if not (isinstance(args, list) and len(args) == 2 and all(_is_number(a) for a in args)) or not (
            0 <= args[1] < math.inf
        ):
            raise ctx.fail(sub, "[mu, sigma] with finite sigma >= 0", args)
        _check_number(ctx, sub, args[0], {**meta, "integer": False}, f"a mean that is {num}")
        args = [float(a) for a in args]
    return Param(kind, tuple(args), **kw)


def _convert_scalar(ctx: _Ctx, key: str, tp: type, v: object, meta: dict) -> object:
    if tp is bool:
        if not isinstance(v, bool):
            raise ctx.fail(key, "true or false", v)
        return v
    if tp is int:
        return _check_number(ctx, key, v, {**meta, "integer": True}, _number_text({**meta, "integer": True}))
    if tp is float:
        return float(_check_number(ctx, key, v, meta, _number_text(meta)))
    if tp is str:
        choices = meta.get("choices")
        if choices is not None:
            if v not in choices:
                raise ctx.fail(key, "one of " + ", ".join(repr(c) for c in choices), v)
        elif not isinstance(v, str) or (meta.get("nonempty") and not v):
            raise ctx.fail(key, "a non-empty string" if meta.get("nonempty") else "a string", v)
        elif meta.get("pattern") and not re.match(meta["pattern"], v):
            raise ctx.fail(key, "a name of letters, digits, '_', '.', '-' not starting with '.'", v)
        return v
    if tp is dict:
        if not (isinstance(v, dict) and all(isinstance(k, str) for k in v)):
            raise ctx.fail(key, "a mapping of names to values", v)
        return dict(v)
    if tp is typing.Any:
        return v
    raise TypeError(f"recipe field {key}: unsupported type {tp!r}")


def _convert_union(ctx: _Ctx, key: str, members: tuple, v: object) -> object:
    """A union of dataclasses told apart by their ``kind`` field (first member when ``kind`` is absent)."""
    kinds = {m.__dataclass_fields__["kind"].default: m for m in members}
    if not isinstance(v, dict):
        raise ctx.fail(key, "a mapping with 'kind' one of " + ", ".join(repr(k) for k in kinds), v)
    kind = v.get("kind", next(iter(kinds)))
    if not isinstance(kind, str) or kind not in kinds:
        raise ctx.fail(f"{key}.kind", "one of " + ", ".join(repr(k) for k in kinds), kind)
    return build_dataclass(kinds[kind], v, key, ctx)


def _convert_tuple(ctx: _Ctx, key: str, args: tuple, v: object, meta: dict) -> tuple:
    if not isinstance(v, list | tuple):
        raise ctx.fail(key, "a list", v)
    if len(args) == 2 and args[1] is Ellipsis:
        if meta.get("nonempty") and not v:
            raise ctx.fail(key, "a non-empty list", v)
        return tuple(_convert(ctx, f"{key}[{i}]", args[0], x, {}) for i, x in enumerate(v))
    if len(v) != len(args):
        raise ctx.fail(key, f"a list of {len(args)} values", v)
    return tuple(
        _convert(ctx, f"{key}[{i}]", a, x, meta) for i, (a, x) in enumerate(zip(args, v, strict=True))
    )


def _convert(ctx: _Ctx, key: str, tp: object, v: object, meta: dict) -> object:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        rest = tuple(a for a in args if a is not type(None))
        if v is None and len(rest) < len(args):
            return None
        if len(rest) == 1:
            return _convert(ctx, key, rest[0], v, meta)
        return _convert_union(ctx, key, rest, v)
    if ctx.shorthand is not None:
        v = ctx.shorthand(tp, v)
    if tp is Param:
        return _convert_param(ctx, key, v, meta)
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return build_dataclass(tp, v, key, ctx)
    if origin is list:
        if not isinstance(v, list):
            raise ctx.fail(key, "a list", v)
        if meta.get("nonempty") and not v:
            raise ctx.fail(key, "a non-empty list", v)
        return [_convert(ctx, f"{key}.{i}", args[0], x, {}) for i, x in enumerate(v)]
    if origin is dict:
        if not (isinstance(v, dict) and all(isinstance(k, str) for k in v)):
            raise ctx.fail(key, "a mapping of names to values", v)
        return {k: _convert(ctx, f"{key}.{k}", args[1], x, {}) for k, x in v.items()}
    if origin is tuple:
        return _convert_tuple(ctx, key, args, v, meta)
    return _convert_scalar(ctx, key, cast(type, tp), v, meta)


def build_dataclass(
    cls: type,
    data: object,
    key: str = "",
    ctx: _Ctx | str = "",
    *,
    error: type[RecipeError] = RecipeError,
    shorthand: Shorthand | None = None,
) -> typing.Any:
    """Build ``cls`` from a mapping, checking every key, type and range.

    Args:
        cls: A recipe dataclass.
        data: The YAML mapping (None means all defaults).
        key: Dotted key of ``data`` in the recipe (``""`` at the top).
        ctx: The recipe's file name, first word of every message ("" for none), or a context.
        error: The :class:`~gttdata.errors.RecipeError` subclass raised.
        shorthand: Optional ``(type, value) -> value`` hook applied before each conversion.

    Raises:
        RecipeError: One line naming the file, the key, what was expected and what was found (also
            for a value the dataclass's ``__post_init__`` rejects with ValueError or TypeError).
    """
    ctx = _Ctx(ctx, error, shorthand) if isinstance(ctx, str) else ctx
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ctx.fail(key or "<top>", f"a mapping of {cls.__name__} fields", data)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    hints = typing.get_type_hints(cls)
    for k in data:
        if k not in fields:
            raise ctx.at(
                f"{key}.{k}" if key else str(k), f"unknown key (expected one of: {', '.join(fields)})"
            )
    values = {}
    for name, f in fields.items():
        sub = f"{key}.{name}" if key else name
        if name in data:
            values[name] = _convert(ctx, sub, hints[name], data[name], dict(f.metadata))
        elif f.metadata.get("nonempty") or (
            f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        ):
            raise ctx.fail(sub, "a value (this key is required)", None)
    try:
        return cls(**values)
    except (TypeError, ValueError) as exc:
        raise ctx.at(key or "recipe", str(exc)) from exc


def read_yaml_mapping(path: str | Path, *, error: type[RecipeError] = RecipeError) -> dict:
    """The top-level mapping of a YAML recipe file (an empty file is an empty mapping).

    Raises:
        RecipeError: ``<path>: recipe file not found``, invalid YAML (with its line), or not a mapping.
    """
    source = str(path)
    try:
        text = Path(path).read_text()
    except FileNotFoundError as exc:
        raise error(f"{source}: recipe file not found") from exc
    except IsADirectoryError as exc:
        raise error(f"{source}: expected a recipe file, found a directory") from exc
    try:
        data = load_yaml(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}: " if mark is not None else ""
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())
        raise error(f"{source}: {where}not valid YAML ({problem})") from exc
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise error(f"{source}: <top>: expected a mapping of recipe sections, found {type(data).__name__}")
    return data


def _resolve(value: object, base: Path) -> object:
    if (
        not isinstance(value, str)
        or not value
        or value.startswith(("$", "~", "cache:"))
        or os.path.isabs(value)
    ):
        return value
    return os.path.normpath(base / value)


def resolve_paths(cls: type, data: object, base: str | Path) -> object:
    """Resolve the relative file paths a raw recipe mapping names against ``base`` (its file's folder).

    Fields marked ``path`` in their metadata are rewritten (``str`` or lists of ``str``); nested
    dataclasses, lists of them and ``kind``-tagged unions are walked. Absolute paths and ones starting
    with ``$``, ``~`` or ``cache:`` (the motion cache) are left as written. Values not matching the schema are left for
    :func:`build_dataclass` to report.

    Args:
        cls: The recipe dataclass ``data`` describes.
        data: Raw YAML data (not modified).
        base: The recipe file's folder.

    Returns:
        A copy of ``data`` with the marked paths resolved.
    """
    if not (dataclasses.is_dataclass(cls) and isinstance(data, dict)):
        return data
    base = Path(base)
    hints = typing.get_type_hints(cls)
    out = dict(data)
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        v = data[f.name]
        if f.metadata.get("path"):
            out[f.name] = [_resolve(x, base) for x in v] if isinstance(v, list) else _resolve(v, base)
        else:
            out[f.name] = _resolve_nested(hints[f.name], v, base)
    return out


def _resolve_nested(tp: object, v: object, base: Path) -> object:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        members = [a for a in args if isinstance(a, type) and dataclasses.is_dataclass(a)]
        if isinstance(v, dict) and members:
            kinds = {
                m.__dataclass_fields__["kind"].default: m for m in members if "kind" in m.__dataclass_fields__
            }
            kind = v.get("kind")
            chosen = kinds.get(kind, members[0]) if kinds and isinstance(kind, str) else members[0]
            return resolve_paths(chosen, v, base)
        others = [a for a in args if a is not type(None)]
        return _resolve_nested(others[0], v, base) if len(others) == 1 else v
    if isinstance(tp, type) and dataclasses.is_dataclass(tp):
        return resolve_paths(tp, v, base)
    if origin in (list, tuple) and isinstance(v, list) and args:
        return [_resolve_nested(args[0], x, base) for x in v]
    return v


def to_plain(obj: object) -> object:
    """A recipe object as plain YAML/JSON data (dicts, lists, numbers, strings)."""
    if isinstance(obj, Param):
        return obj.to_yaml()
    if dataclasses.is_dataclass(obj):
        # Fields marked ``omit_default`` are left out at their default, so that adding such a field
        # keeps the canonical form (and the hash) of every recipe that does not use it.
        return {
            f.name: to_plain(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if not (f.metadata.get("omit_default") and getattr(obj, f.name) == f.default)
        }
    if isinstance(obj, tuple | list):
        return [to_plain(x) for x in obj]
    if isinstance(obj, dict):
        return {str(k): to_plain(v) for k, v in obj.items()}
    return obj


def apply_overrides(
    data: dict, overrides: Sequence[str], source: str, *, error: type[Exception] = RecipeError
) -> dict:
    """Apply ``key.sub=value`` overrides (values parsed as YAML scalars) to a raw recipe mapping in place.

    The one override syntax of every gtt recipe (generate, train, evaluate). A list is indexed by
    position (``splits.0``) or by an element's ``name`` (``splits.train``).

    Args:
        data: Raw recipe mapping (changed in place and returned).
        overrides: E.g. ``["capture.sigma_px=4", "stages.0.steps=10", "methods=[pseudo,dloe]"]``.
        source: Recipe name or path, first word of every error.
        error: Exception type raised for a malformed override (each caller's recipe error).
    """
    for ov in overrides:
        key, sep, text = ov.partition("=")
        if not sep or not key.strip():
            raise error(f"{source}: override {ov!r}: expected key.sub=value")
        try:
            value = load_yaml(text)
        except yaml.YAMLError as exc:
            raise error(
                f"{source}: override {key}: value {text!r} is not valid YAML ({yaml_error_line(exc)})"
            ) from exc
        node: object = data
        parts = key.strip().split(".")
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            where = ".".join(parts[: i + 1])
            if isinstance(node, list):
                idx = next(
                    (j for j, x in enumerate(node) if isinstance(x, dict) and x.get("name") == part), None
                )
                if idx is None and part.isdigit() and int(part) < len(node):
                    idx = int(part)
                if idx is None:
                    raise error(f"{source}: override {where}: no list element named or numbered {part!r}")
                if last:
                    node[idx] = value
                else:
                    node = node[idx]
            elif isinstance(node, dict):
                if last:
                    node[part] = value
                else:
                    if not isinstance(node.get(part), dict | list):
                        node[part] = {}
                    node = node[part]
            else:
                raise error(f"{source}: override {where}: cannot set a key inside a {type(node).__name__}")
    return data
