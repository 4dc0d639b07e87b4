"""``serpar import --spec F.yaml``: how data as published becomes a recording, in one file that
travels with the data (docs/recording.md, docs/examples/tx40_import.yaml).

The keys (SPEC_KEYS): ``map`` (source column: channel, as ``--map``; with several files a
column is ``<file stem>.<column>``), ``source_rate`` (Hz, as ``--rate``: a file without a time
column), ``scale`` (a multiplier per channel, source column, matrix source or channel family),
``joint_map`` (motor side to joint side, below), ``rate`` (the output rate, by anti-aliased
decimation), ``sigma_from_rest`` ([t0, t1] s: each channel's noise sigma from a rest segment)
and ``robot`` (free text, recorded in meta.model).

``joint_map``: joint angles ``q = A theta_m + offsets`` with ``matrix`` A, or ``motor_matrix``
R with ``theta_m = R (q - offsets)`` (A = inv(R): the form gear ratios are published in);
torques ``tau = torque_matrix tau_m``, by default inv(A).T, the map that conserves power
(tau . dq = tau_m . dtheta_m). ``from`` names the channel families it maps (motor-side values
imported under these names), ``to`` what they become (default: the same names, replaced).

Read into frozen dataclasses validated on construction; every problem is one ConfigError
naming the file and the key."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from serpar.errors import ConfigError
from serpar.sim.channels import ARM_FAMILIES, KNOWN_HELP, MAX_ARM_JOINTS, is_channel
from serpar.sim.config_io import from_dict, read_yaml
from serpar.sim.config_types import convert

SPEC_KEYS = ("map", "source_rate", "scale", "joint_map", "rate", "sigma_from_rest", "robot")
JOINT_MAP_KEYS = ("matrix", "motor_matrix", "offsets", "torque_matrix", "from", "to")
MAX_CONDITION = 1e12
"""A joint map whose matrix is worse conditioned than this is singular for our purpose: the
joint angles would be motor noise amplified beyond any meaning."""
ANGLE, VELOCITY, TORQUE = "angle", "velocity", "torque"
FAMILY_KIND = {"q": ANGLE, "dq": VELOCITY, "tau_J": TORQUE, "tau_J_d": TORQUE, "tau_drive": TORQUE}
"""What a joint map does to each arm family: angles get A and the offsets, velocities A,
torques the torque matrix."""

Matrix = tuple[tuple[float, ...], ...]


def _square(m: Matrix, what: str) -> np.ndarray:
    a = np.asarray(m, float) if m and all(len(r) == len(m) for r in m) else None
    if a is None or not 1 <= a.shape[0] <= MAX_ARM_JOINTS:
        shape = "x".join(str(len(r)) for r in m) or "empty"
        raise ConfigError(f"{what}: expected a square n x n list of rows (n = 1.."
                          f"{MAX_ARM_JOINTS}), got rows of {shape}")
    return a


def _nonsingular(a: np.ndarray, what: str) -> None:
    cond = float(np.linalg.cond(a)) if np.all(np.isfinite(a)) else math.inf
    if np.linalg.det(a) == 0 or not cond <= MAX_CONDITION:
        raise ConfigError(f"{what} is singular (condition number {cond:.3g} > "
                          f"{MAX_CONDITION:g}): motor and joint sides must map one to one")


@dataclass(frozen=True)
class JointMap:
    """A linear map from the motor side to the joint side (module docstring)."""

    matrix: Matrix
    """A: q = A theta_m + offsets."""
    offsets: tuple[float, ...] = ()
    """[rad], one per joint; () is zeros."""
    torque_matrix: Matrix | None = None
    """tau = torque_matrix tau_m; None: inv(A).T (power-conserving)."""
    sources: tuple[str, ...] = ("q",)
    """``from``: the channel families the motor-side values were imported under."""
    targets: tuple[str, ...] = ()
    """``to``: the joint-side families they become; () is the same as ``sources``."""
    motor_matrix: Matrix | None = None
    """R as given (theta_m = R (q - offsets)), for the record; ``matrix`` is inv(R)."""

    def __post_init__(self) -> None:
        a = _square(self.matrix, "joint_map.matrix")
        _nonsingular(a, "joint_map.matrix")
        n = a.shape[0]
        if self.offsets and len(self.offsets) != n:
            raise ConfigError(f"joint_map.offsets: {len(self.offsets)} values for a {n}-joint "
                              "matrix; give one per joint (rad)")
        if self.torque_matrix is not None and _square(self.torque_matrix, "joint_map."
                                                      "torque_matrix").shape[0] != n:
            raise ConfigError(f"joint_map.torque_matrix: not {n} x {n} like joint_map.matrix")
        if not self.sources:
            raise ConfigError("joint_map.from: name the channel families it maps, e.g. [q, "
                              "tau_drive]")
        if self.targets and len(self.targets) != len(self.sources):
            raise ConfigError(f"joint_map.to: {len(self.targets)} families for "
                              f"{len(self.sources)} in joint_map.from; give one per family")
        bad = [t for t in self.to if t not in FAMILY_KIND]
        if bad:
            raise ConfigError(f"joint_map.to: {', '.join(bad)} is not an arm channel family; "
                              f"valid: {', '.join(ARM_FAMILIES)}")
        for src, dst in zip(self.sources, self.to, strict=True):
            if src in FAMILY_KIND and FAMILY_KIND[src] != FAMILY_KIND[dst]:
                raise ConfigError(f"joint_map: from {src} (a {FAMILY_KIND[src]}) to {dst} (a "
                                  f"{FAMILY_KIND[dst]}); a family maps onto one of its kind")
        for key, families in (("from", self.sources), ("to", self.to)):
            if len(set(families)) != len(families):
                raise ConfigError(f"joint_map.{key} names a family twice")

    @property
    def n(self) -> int:
        return len(self.matrix)

    @property
    def to(self) -> tuple[str, ...]:
        return self.targets or self.sources

    @property
    def a(self) -> np.ndarray:
        return np.asarray(self.matrix, float)

    @property
    def offset(self) -> np.ndarray:
        return np.asarray(self.offsets, float) if self.offsets else np.zeros(self.n)

    @property
    def t(self) -> np.ndarray:
        """The torque map: given, or inv(A).T."""
        if self.torque_matrix is not None:
            return np.asarray(self.torque_matrix, float)
        return np.linalg.inv(self.a).T + 0.0  # + 0.0: no -0.0 in the record

    def power_error(self) -> float:
        """max |T^T A - I|: 0 when torques and angles conserve power (tau . dq = tau_m .
        dtheta_m)."""
        return float(np.max(np.abs(self.t.T @ self.a - np.eye(self.n))))

    def as_dict(self) -> dict[str, object]:
        return {"matrix": self.a.tolist(), "motor_matrix": self.motor_matrix,
                "offsets": self.offset.tolist(),
                "torque_matrix": self.t.tolist(), "torque_matrix_given": self.torque_matrix
                is not None, "power_error": self.power_error(), "from": list(self.sources),
                "to": list(self.to)}


@dataclass(frozen=True)
class ImportSpec:
    """``--spec F.yaml`` validated (module docstring)."""

    path: str = "spec"
    """Where it was read from (for messages and the recording's import notes)."""
    map: dict[str, str] = field(default_factory=dict)
    """{channel: source column}; empty: none given."""
    source_rate: float | None = None
    scale: dict[str, float] = field(default_factory=dict)
    joint_map: JointMap | None = None
    rate: float | None = None
    """The output rate [Hz]; None: the source's."""
    sigma_from_rest: tuple[float, float] | None = None
    """[t0, t1] seconds from the first sample."""
    robot: str | None = None

    def __post_init__(self) -> None:
        for key in ("source_rate", "rate"):
            value = getattr(self, key)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{key}: {value:g} Hz; a sample rate is > 0")
        # a matrix source maps a numbered family at once: q for q.1..q.7 -> q1..q7
        bad = [c for c in self.map if not (is_channel(c) or is_channel(f"{c}1"))]
        if bad:
            raise ConfigError(f"map: unknown channel(s) {', '.join(bad)}; valid: {KNOWN_HELP}")
        for key, value in self.scale.items():
            if not math.isfinite(value) or value == 0:
                raise ConfigError(f"scale: {key}: {value!r}; a finite multiplier, not 0")
        if self.sigma_from_rest is not None:
            t0, t1 = self.sigma_from_rest
            if not 0 <= t0 < t1:
                raise ConfigError(f"sigma_from_rest: [{t0:g}, {t1:g}]; seconds from the first "
                                  "sample, 0 <= t0 < t1")

    def as_dict(self) -> dict[str, object]:
        return {"file": self.path, "map": {c: ch for ch, c in self.map.items()},
                "source_rate_hz": self.source_rate, "scale": dict(self.scale),
                "joint_map": self.joint_map.as_dict() if self.joint_map else None,
                "rate_hz": self.rate, "sigma_from_rest_s": (list(self.sigma_from_rest)
                                                            if self.sigma_from_rest else None),
                "robot": self.robot}


def _get(hint: Any, raw: Any, where: str) -> Any:
    return convert(hint, raw, where, from_dict)


def _mapping(raw: Any, where: str, values: Any) -> dict[str, Any]:
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping, got {type(raw).__name__}")
    return {_get(str, k, f"{where} key"): _get(values, v, f"{where}.{k}") for k, v in raw.items()}


def _check_keys(raw: Any, valid: tuple[str, ...], where: str) -> dict[str, Any]:
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a mapping with keys {', '.join(valid)}, got "
                          f"{type(raw).__name__}")
    unknown = sorted(str(k) for k in raw if k not in valid)
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; valid: "
                          f"{', '.join(valid)}")
    return raw


def _families(raw: Any, where: str) -> tuple[str, ...]:
    value = _get(str | tuple[str, ...], raw, where)
    return (value,) if isinstance(value, str) else value


def joint_map_from(raw: Any) -> JointMap:
    values = _check_keys(raw, JOINT_MAP_KEYS, "joint_map")
    if ("matrix" in values) == ("motor_matrix" in values):
        raise ConfigError("joint_map: give one of matrix (q = A theta_m + offsets) or "
                          "motor_matrix (theta_m = R (q - offsets))")
    grid = tuple[tuple[float, ...], ...]
    motor = None
    if "motor_matrix" in values:
        motor = _get(grid, values["motor_matrix"], "joint_map.motor_matrix")
        r = _square(motor, "joint_map.motor_matrix")
        _nonsingular(r, "joint_map.motor_matrix")
        matrix = tuple(tuple(float(v) for v in row) for row in np.linalg.inv(r) + 0.0)
    else:
        matrix = _get(grid, values["matrix"], "joint_map.matrix")
    torque = values.get("torque_matrix")
    offsets = _get(tuple[float, ...], values.get("offsets", []), "joint_map.offsets")
    return JointMap(matrix, offsets,
                    None if torque is None else _get(grid, torque, "joint_map.torque_matrix"),
                    _families(values.get("from", "q"), "joint_map.from"),
                    _families(values["to"], "joint_map.to") if "to" in values else (), motor)


def spec_from(values: Any, path: str = "spec") -> ImportSpec:
    values = _check_keys(values, SPEC_KEYS, "spec")
    mapping: dict[str, str] = {}
    for col, chan in _mapping(values.get("map", {}), "map", str).items():
        if chan in mapping:
            raise ConfigError(f"map: channel {chan!r} is given twice ({mapping[chan]!r} and "
                              f"{col!r})")
        mapping[chan] = col
    optional = {"source_rate": float, "rate": float, "robot": str,
                "sigma_from_rest": tuple[float, float]}
    return ImportSpec(
        path, mapping, scale=_mapping(values.get("scale", {}), "scale", float),
        joint_map=joint_map_from(values["joint_map"]) if "joint_map" in values else None,
        **{k: _get(hint, values[k], k) for k, hint in optional.items()
           if values.get(k) is not None})


def load_spec(path: str | Path) -> ImportSpec:
    """Read ``--spec F.yaml``; a one-line ConfigError naming the file on any problem."""
    p = Path(path)
    values = read_yaml(p, "spec")
    try:
        return spec_from({} if values is None else values, str(p))
    except ConfigError as exc:
        raise ConfigError(f"{p.name}: {str(exc).removeprefix('spec: ')}") from None




def _numbered(name: str) -> tuple[str, int | None]:
    head = name.rstrip("0123456789")
    return head, int(name[len(head):]) if head != name else None


def compact(names: list[str] | tuple[str, ...]) -> str:
    """Channel names for a note, runs of three or more of one family joined: ``q1..q6``."""
    runs: list[list[str]] = []
    for name in names:
        head, k = _numbered(name)
        last = _numbered(runs[-1][-1]) if runs else ("", None)
        if k is not None and last[1] is not None and head == last[0] and k == last[1] + 1:
            runs[-1].append(name)
        else:
            runs.append([name])
    return ", ".join(f"{r[0]}..{r[-1]}" if len(r) > 2 else ", ".join(r) for r in runs)
