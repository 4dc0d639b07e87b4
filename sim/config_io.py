"""YAML at the command-line edge: dicts onto the frozen config dataclasses, unknown keys rejected."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from serpar.errors import ConfigError

T = TypeVar("T")


def from_dict(cls: type[T], values: dict[str, Any], where: str = "config") -> T:
    """Build dataclass `cls` from `values`; nested dataclasses from nested dicts."""
    if not isinstance(values, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(values).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; valid: {', '.join(fields)}")
    hints = typing.get_type_hints(cls)
    kwargs: dict[str, Any] = {}
    for name, raw in values.items():
        hint = hints[name]
        if dataclasses.is_dataclass(hint) and isinstance(raw, dict):
            kwargs[name] = from_dict(hint, raw, f"{where}.{name}")  # type: ignore[arg-type]
        elif isinstance(raw, list):
            kwargs[name] = tuple(tuple(v) if isinstance(v, list) else v for v in raw)
        else:
            kwargs[name] = raw
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def load_yaml_config(cls: type[T], path: str | Path) -> T:
    """Read a YAML file into dataclass `cls`; a one-line ConfigError on any problem."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"config file {p} not found")
    try:
        values = yaml.safe_load(p.read_text()) or {}
    except yaml.YAMLError as exc:
        first = str(exc).splitlines()[0] if str(exc) else "parse error"
        raise ConfigError(f"config file {p} is not valid YAML: {first}") from None
    return from_dict(cls, values, where=p.name)
