"""The diagnosis model file (``<stem>.model.json``, written by report_html.py): read and validated
into frozen data, one-line ConfigErrors that name the problem and the valid choices.

Schema: ``{"source": str, "kind": str, "effects": [name, ...], "params": {block: {"values":
[...], "std": [...], "names": [...]}}, "prior_model": str, "evidence": {effect: str},
"empirical": [term, ...]}`` (the last three optional: the model a diagnosis was run against,
why each effect was established, and the empirical terms describing what no effect explains). ``effects`` are the
selected effects in the order they were added; ``params`` holds one block per effect and the
family's baseline block (refitted on every recording, so not part of the model proper).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from serpar.errors import ConfigError

KEYS = ("source", "kind", "effects", "params")
OPTIONAL_KEYS = ("prior_model", "evidence", "empirical")
BLOCK_KEYS = ("values", "std", "names")


@dataclass(frozen=True)
class ParamBlock:
    """One fitted block: parameter names, values and 1-sigma uncertainties."""

    names: tuple[str, ...]
    values: tuple[float, ...]
    std: tuple[float, ...]

    def __post_init__(self) -> None:
        if not (len(self.names) == len(self.values) == len(self.std)):
            raise ConfigError(f"a parameter block has {len(self.names)} names, "
                              f"{len(self.values)} values and {len(self.std)} std")
        if len(set(self.names)) != len(self.names):
            raise ConfigError(f"parameter names repeat in {self.names}")

    def as_dict(self) -> dict[str, float]:
        return dict(zip(self.names, self.values))


@dataclass(frozen=True)
class DiagnosisModel:
    """A validated model file: the effects a diagnosis found and their fitted parameters."""

    path: str
    source: str
    kind: str
    effects: tuple[str, ...]
    blocks: tuple[tuple[str, ParamBlock], ...]
    """(block name, block) in file order: every effect's, plus the baseline's."""
    prior_model: str | None = None
    evidence: tuple[tuple[str, str], ...] = ()
    """(effect, why it was established) as the diagnosis stated it."""
    empirical: tuple[object, ...] = ()
    """The diagnosis's empirical terms, kept as written: a description of residual, not physics."""

    def __post_init__(self) -> None:
        names = [b for b, _ in self.blocks]
        if len(set(names)) != len(names):
            raise ConfigError(f"{self.path}: parameter blocks repeat")
        if len(set(self.effects)) != len(self.effects):
            raise ConfigError(f"{self.path}: effects repeat: {', '.join(self.effects)}")
        missing = [e for e in self.effects if e not in names]
        if missing:
            raise ConfigError(f"{self.path}: effect(s) {', '.join(missing)} have no block in "
                              f"params (blocks: {', '.join(names) or 'none'})")

    def block(self, name: str) -> ParamBlock:
        for b, block in self.blocks:
            if b == name:
                return block
        raise ConfigError(f"{self.path}: no parameter block {name!r}; blocks: "
                          f"{', '.join(b for b, _ in self.blocks)}")

    @property
    def baseline_blocks(self) -> tuple[str, ...]:
        """Blocks that are not effects: the recording's baseline (tares, tool offset...)."""
        return tuple(b for b, _ in self.blocks if b not in self.effects)


def _numbers(where: str, raw: object, finite_nonneg: bool = False) -> tuple[float, ...]:
    if not isinstance(raw, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                            for v in raw):
        raise ConfigError(f"{where}: expected a list of numbers")
    out = tuple(float(v) for v in raw)
    if not all(math.isfinite(v) and (v >= 0 or not finite_nonneg) for v in out):
        raise ConfigError(f"{where}: values must be finite" + (" and >= 0" if finite_nonneg else ""))
    return out


def _block(where: str, raw: object) -> ParamBlock:
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping with keys {', '.join(BLOCK_KEYS)}")
    if set(raw) != set(BLOCK_KEYS):
        raise ConfigError(f"{where}: keys {', '.join(sorted(raw))}; valid: {', '.join(BLOCK_KEYS)} "
                          "(all three)")
    names = raw["names"]
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        raise ConfigError(f"{where}.names: expected a list of non-empty strings")
    try:
        return ParamBlock(tuple(names), _numbers(f"{where}.values", raw["values"]),
                          _numbers(f"{where}.std", raw["std"], finite_nonneg=True))
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def parse_model(data: object, path: str = "model") -> DiagnosisModel:
    """A :class:`DiagnosisModel` from the decoded JSON of a model file."""
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a JSON object with keys {', '.join(KEYS)}")
    unknown = sorted(set(data) - set(KEYS) - set(OPTIONAL_KEYS))
    missing = [k for k in KEYS if k not in data]
    if unknown or missing:
        raise ConfigError(f"{path}: " + (f"unknown key(s) {', '.join(unknown)}; " if unknown else "")
                          + (f"missing key(s) {', '.join(missing)}; " if missing else "")
                          + f"valid: {', '.join(KEYS + OPTIONAL_KEYS)}")
    for key in ("source", "kind"):
        if not isinstance(data[key], str):
            raise ConfigError(f"{path}: {key} must be a string")
    effects = data["effects"]
    if not isinstance(effects, list) or not all(isinstance(e, str) and e for e in effects):
        raise ConfigError(f"{path}: effects must be a list of effect names")
    params = data["params"]
    if not isinstance(params, dict):
        raise ConfigError(f"{path}: params must be a mapping of block name -> "
                          f"{{{', '.join(BLOCK_KEYS)}}}")
    prior = data.get("prior_model")
    if prior is not None and not isinstance(prior, str):
        raise ConfigError(f"{path}: prior_model must be a string (a path)")
    blocks = tuple((str(name), _block(f"{path}: params.{name}", raw))
                   for name, raw in params.items())
    evidence = data.get("evidence", {})
    if not isinstance(evidence, dict) or not all(isinstance(v, str) for v in evidence.values()):
        raise ConfigError(f"{path}: evidence must map effect names to text")
    empirical = data.get("empirical", [])
    if not isinstance(empirical, list):
        raise ConfigError(f"{path}: empirical must be a list of terms")
    return DiagnosisModel(path, data["source"], data["kind"], tuple(effects), blocks, prior,
                          tuple((str(k), v) for k, v in evidence.items()), tuple(empirical))


def read_model_file(path: str | Path) -> DiagnosisModel:
    """Read and validate a model file (ConfigError, one line, on any problem)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"model file {p} not found (a <stem>.model.json written by "
                          "`serpar diagnose --report`)")
    try:
        data = json.loads(p.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"model file {p} is not valid JSON: {exc}") from None
    return parse_model(data, str(p))


def model_dict(model: DiagnosisModel) -> dict[str, object]:
    """The JSON form of ``model`` (inverse of :func:`parse_model`)."""
    out: dict[str, object] = {
        "source": model.source, "kind": model.kind, "effects": list(model.effects),
        "params": {b: {"values": list(k.values), "std": list(k.std), "names": list(k.names)}
                   for b, k in model.blocks}}
    if model.prior_model is not None:
        out["prior_model"] = model.prior_model
    if model.evidence:
        out["evidence"] = dict(model.evidence)
    if model.empirical:
        out["empirical"] = list(model.empirical)
    return out
