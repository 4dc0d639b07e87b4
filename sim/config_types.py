"""Strict types for config values read from YAML: a value must be of its field's annotated type.

YAML is loose (``"false"`` is a string, ``3.5`` is not a hole list, ``table5`` is not a
mapping), and the frozen config dataclasses validate ranges, not types: a string compared with
a number fails deep inside with a Python message, a non-empty string counts as ``True``. So
every value read from a file is checked against the field's annotation here, before the
dataclass is built, and a mismatch is one :class:`ConfigError` naming the key, what it expects
and what it got."""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Callable
from typing import Any

from serpar.errors import ConfigError

Build = Callable[[type, dict, str], Any]
"""How a nested dataclass is built from its mapping (config_io.from_dict, passed in to avoid a
cycle)."""


def describe(hint: Any) -> str:
    """What a value of type `hint` looks like, in the words a YAML user reads."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is bool:
        return "true or false"
    if hint is int:
        return "an integer"
    if hint is float:
        return "a number"
    if hint is str:
        return "a string"
    if hint is type(None):
        return "null"
    if dataclasses.is_dataclass(hint):
        keys = ", ".join(f.name for f in dataclasses.fields(hint))
        return f"a mapping with keys {keys}"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(a) for a in args)
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])}"
        return f"a list of {len(args)} {_plural(args[0]) if len(set(args)) == 1 else 'values'}"
    return getattr(hint, "__name__", str(hint))


def _plural(hint: Any) -> str:
    words = {bool: "true/false values", int: "integers", float: "numbers", str: "strings"}
    if hint in words:
        return words[hint]
    if dataclasses.is_dataclass(hint):
        return f"mappings ({describe(hint)})"
    return describe(hint)


def _got(raw: object) -> str:
    kind = {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "a mapping", type(None): "null"}.get(type(raw), type(raw).__name__)
    shown = repr(raw)
    return f"{shown if len(shown) <= 60 else shown[:57] + '...'} ({kind})"


class _Mismatch(Exception):
    """The value does not fit this annotation (caught to try a union's other members)."""


def convert(hint: Any, raw: Any, where: str, build: Build) -> Any:
    """`raw` as a value of type `hint`, or a ConfigError saying what `where` expects."""
    try:
        return _convert(hint, raw, where, build)
    except _Mismatch:
        raise ConfigError(f"{where}: expected {describe(hint)}, got {_got(raw)}") from None


def _convert(hint: Any, raw: Any, where: str, build: Build) -> Any:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is Any:
        return raw
    if hint is bool:
        if isinstance(raw, bool):
            return raw
        raise _Mismatch
    if hint is int:
        if isinstance(raw, int) and not isinstance(raw, bool):
            return raw
        raise _Mismatch
    if hint is float:
        if isinstance(raw, (int, float)) and not isinstance(raw, bool):
            if not math.isfinite(raw):
                raise ConfigError(f"{where}: expected a finite number, got {raw!r}")
            return float(raw)
        raise _Mismatch
    if hint is str:
        if isinstance(raw, str):
            return raw
        raise _Mismatch
    if hint is type(None):
        if raw is None:
            return None
        raise _Mismatch
    if dataclasses.is_dataclass(hint):
        if isinstance(raw, dict):
            return build(hint, raw, where)  # nested errors name their own key
        raise _Mismatch
    if origin in (typing.Union, types.UnionType):
        for member in args:
            try:
                return _convert(member, raw, where, build)
            except _Mismatch:
                continue
        raise _Mismatch
    if origin is tuple:
        if not isinstance(raw, (list, tuple)):
            raise _Mismatch
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(convert(args[0], v, f"{where}[{i}]", build) for i, v in enumerate(raw))
        if len(raw) != len(args):
            raise ConfigError(f"{where}: expected {describe(hint)}, got {len(raw)} values")
        return tuple(convert(a, v, f"{where}[{i}]", build) for i, (a, v) in enumerate(zip(args, raw)))
    if isinstance(hint, type) and isinstance(raw, hint):
        return raw
    raise _Mismatch
