"""YAML at the command-line edge: dicts onto the frozen config dataclasses, unknown keys rejected."""

from __future__ import annotations

import dataclasses
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from serpar.errors import ConfigError
from serpar.sim.config_types import convert

T = TypeVar("T")


def from_dict(cls: type[T], values: dict[str, Any], where: str = "config") -> T:
    """Build dataclass `cls` from `values`; nested dataclasses from nested dicts."""
    if not isinstance(values, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(values).__name__}")
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(k if isinstance(k, str) and k.isidentifier() else repr(k)
                     for k in set(values) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; valid: {', '.join(fields)}")
    hints = typing.get_type_hints(cls)
    kwargs = {name: convert(hints[name], raw, _key(where, name), from_dict) for name, raw in values.items()}
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _key(where: str, name: str) -> str:
    """"run.yaml" + "holes" -> "run.yaml: holes"; "run.yaml: stewart" + "stroke" -> "run.yaml: stewart.stroke"."""
    return f"{where}.{name}" if ": " in where else f"{where}: {name}"


def read_yaml(path: str | Path, what: str) -> object:
    """The YAML document of ``path``; a one-line ConfigError naming ``what`` file it is, and
    the line and column where the YAML is malformed."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{what} file {p} not found")
    try:
        return yaml.safe_load(p.read_text())
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise ConfigError(f"{what} file {p} is not valid YAML{where}: {exc.problem or exc.context}") from None
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else "parse error"
        raise ConfigError(f"{what} file {p} is not valid YAML: {first}") from None


def load_yaml_config(cls: type[T], path: str | Path) -> T:
    """Read a YAML file into dataclass `cls`; a one-line ConfigError on any problem."""
    p = Path(path)
    values = read_yaml(p, "config")
    try:
        return from_dict(cls, {} if values is None else values, where=p.name)
    except ConfigError as exc:  # a range check of the dataclass names no file: add it
        message = str(exc)
        raise ConfigError(message if message.startswith(p.name) else f"{p.name}: {message}") from None
