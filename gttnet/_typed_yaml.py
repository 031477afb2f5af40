"""Build typed frozen dataclasses from plain YAML data, with one-line errors naming the key."""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Callable

__all__ = ["build_dataclass"]

#: Rewrites a raw value before it is converted to a type, e.g. a scalar shorthand for a mapping.
Shorthand = Callable[[object, object], object]


def build_dataclass(
    cls: type, data: object, key: str = "", *, error: type[Exception], shorthand: Shorthand | None = None
) -> object:
    """Instantiate ``cls`` (a dataclass tree) from nested dicts and lists, validating every field.

    Args:
        cls: The dataclass to build; field types may be dataclasses, ``list[T]``, ``dict[str, T]``,
            ``T | None``, ``Any`` and the scalars float, int, bool, str.
        data: Plain data (YAML-loaded).
        key: Dotted path of ``data`` in the recipe, for messages ("" at the top).
        error: Exception type raised, e.g. ``RecipeError("stages.0.lr: expected float, found 'x'")``.
        shorthand: Optional ``(type, value) -> value`` hook applied before each conversion.

    Raises:
        error: Unknown key, wrong type, or a value the dataclass's ``__post_init__`` rejects.
    """
    return _Builder(error, shorthand).build(cls, data, key)


class _Builder:
    def __init__(self, error: type[Exception], shorthand: Shorthand | None) -> None:
        self.error = error
        self.shorthand = shorthand

    def build(self, cls: type, data: object, key: str) -> object:
        if not isinstance(data, dict):
            raise self.error(f"{key or 'recipe'}: expected a mapping, found {data!r}")
        hints = typing.get_type_hints(cls)
        names = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(data) - set(names))
        if unknown:
            where = f"{key}.{unknown[0]}" if key else unknown[0]
            raise self.error(f"{where}: unknown key; expected one of {', '.join(names)}")
        kwargs = {k: self.convert(hints[k], v, f"{key}.{k}" if key else k) for k, v in data.items()}
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise self.error(f"{key or 'recipe'}: {exc}") from exc

    def convert(self, tp: object, value: object, key: str) -> object:
        origin = typing.get_origin(tp)
        if tp is typing.Any:
            return value
        if origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            if value is None and len(args) < len(typing.get_args(tp)):
                return None
            errors = []
            for a in args:
                try:
                    return self.convert(a, value, key)
                except self.error as exc:
                    errors.append(str(exc))
            raise self.error(errors[0] if errors else f"{key}: unexpected {value!r}")
        if self.shorthand is not None:
            value = self.shorthand(tp, value)
        if dataclasses.is_dataclass(tp):
            return self.build(tp, value, key)
        if origin is list:
            if not isinstance(value, list):
                raise self.error(f"{key}: expected a list, found {value!r}")
            (item,) = typing.get_args(tp)
            return [self.convert(item, v, f"{key}.{i}") for i, v in enumerate(value)]
        if origin is dict or tp is dict:
            if not isinstance(value, dict):
                raise self.error(f"{key}: expected a mapping, found {value!r}")
            args = typing.get_args(tp)
            if not args:
                return {str(k): v for k, v in value.items()}
            return {str(k): self.convert(args[1], v, f"{key}.{k}") for k, v in value.items()}
        return self.scalar(tp, value, key)

    def scalar(self, tp: object, value: object, key: str) -> object:
        is_num = isinstance(value, int | float) and not isinstance(value, bool)
        if tp is float and is_num:
            return float(value)
        if tp is int and is_num and float(value).is_integer():
            return int(value)
        if tp in (bool, str) and isinstance(value, tp):
            return value
        name = getattr(tp, "__name__", None) or str(tp).replace("typing.", "")
        raise self.error(f"{key}: expected {name}, found {value!r}")
