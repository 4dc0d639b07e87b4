"""Registry of concealed-effect twins: effect name -> the domain module that makes it.

Each domain module provides ``EFFECTS: tuple[str, ...]`` and
``make_twin(effect: str | None, magnitude: float | None, seed: int) -> (Recording, answer)``,
and optionally ``MAGNITUDE_RANGE: dict[str, (lo, hi)]`` (the blind bench's draw; default
0.5-2 times the effect's default size). The arm-dynamics domain also takes another arm (a
URDF/MJCF file, ``robot``) and the recording's ``duration``; no other domain does.
"""

from __future__ import annotations

import importlib
from dataclasses import replace
from types import ModuleType

from serpar.errors import ConfigError
from serpar.sim.arm_from_file import arm_from_file
from serpar.sim.recording import Recording

DOMAINS: dict[str, str] = {
    "arm_static": "serpar.twins.arm_static_twin",
    "arm_dynamics": "serpar.twins.arm_dynamics_twin",
    "stewart": "serpar.twins.stewart_twin",
    "stewart_motion": "serpar.twins.stewart_motion_twin",
}
DEFAULT_RANGE = (0.5, 2.0)
ANY_ARM = "arm_dynamics"
MIX = "mix"
"""A drawn mix of effects: the arm-dynamics twin's (with ``--domain arm_dynamics``) or, as
``serpar twin`` has it with no domain, the cell's."""
"""The one domain whose twin takes another arm (``robot``) and a ``duration``."""


def domain_module(domain: str) -> ModuleType:
    if domain not in DOMAINS:
        raise ConfigError(f"unknown twin domain {domain!r}; valid: {', '.join(DOMAINS)}")
    return importlib.import_module(DOMAINS[domain])


def effects() -> dict[str, str]:
    """Every registered effect name -> its domain."""
    out: dict[str, str] = {}
    for domain in DOMAINS:
        for name in domain_module(domain).EFFECTS:
            out[name] = domain
    return out


def domain_of(effect: str | None, domain: str | None) -> str:
    if effect is None:
        return domain or "arm_static"
    if effect == MIX and domain == ANY_ARM:  # the arm-dynamics twin's mix of its own effects
        return ANY_ARM
    table = effects()
    if effect not in table:
        raise ConfigError(f"unknown effect {effect!r}; valid: none, {', '.join(table)}")
    if domain is not None and table[effect] != domain:
        raise ConfigError(f"effect {effect!r} belongs to domain {table[effect]!r}, not {domain!r}")
    return table[effect]


def magnitude_range(effect: str, domain: str) -> tuple[float, float]:
    ranges = getattr(domain_module(domain), "MAGNITUDE_RANGE", {})
    return tuple(ranges.get(effect, DEFAULT_RANGE))  # type: ignore[return-value]


def domain_for(effect: str | None, domain: str | None, robot: str | None = None,
               duration: float | None = None) -> str:
    """The twin's domain; a robot file or a duration (which only the arm-dynamics twin takes)
    makes it arm_dynamics where neither the effect nor ``domain`` names one, and is one line
    for any other domain."""
    if effect is None and domain is None and (robot is not None or duration is not None):
        domain = ANY_ARM
    dom = domain_of(effect, domain)
    domain_module(dom)  # an unknown domain is named first
    if dom != ANY_ARM:
        for flag, value in (("--robot", robot), ("--duration", duration)):
            if value is not None:
                raise ConfigError(f"{flag} is taken by the {ANY_ARM} twin only, not by domain "
                                  f"{dom!r}: give an {ANY_ARM} effect (serpar twin --effect list) "
                                  f"or none, or drop {flag}")
    return dom


def make_twin(effect: str | None, magnitude: float | None, seed: int,
              domain: str | None = None, sigma_error: float = 1.0, robot: str | None = None,
              duration: float | None = None) -> tuple[Recording, dict[str, object]]:
    """The recording of a "real" plant with ``effect`` (None: none) and the answer.
    ``sigma_error``: the recording states its noise sigma this many times too small (the
    instrument is noisier than its data sheet), 1 = stated correctly. ``robot``: the arm's
    URDF/MJCF file (arm_dynamics only; None: the Panda); ``duration``: the recording's length
    [s] (arm_dynamics only; None: the twin's default)."""
    if not 0.1 <= sigma_error <= 10:
        raise ConfigError(f"sigma_error {sigma_error}: valid 0.1..10 (1 = the stated noise is right)")
    dom = domain_for(effect, domain, robot, duration)
    kwargs: dict[str, object] = {}
    if robot is not None:
        kwargs["arm"] = arm_from_file(str(robot))
    if duration is not None:
        kwargs["duration"] = duration
    rec, answer = domain_module(dom).make_twin(effect, magnitude, seed, **kwargs)
    if sigma_error != 1.0:
        model = dict(rec.meta.model)
        measurements = model.get("measurements")
        if isinstance(measurements, dict) and "sigma_m" in measurements:  # static sets
            model["measurements"] = {**measurements,
                                     "sigma_m": float(measurements["sigma_m"]) / sigma_error}
        meta = replace(rec.meta, model=model,
                       noise_sigma={k: v / sigma_error for k, v in rec.meta.noise_sigma.items()})
        rec = replace(rec, meta=meta)
        answer = {**answer, "stated_sigma_optimistic_by": sigma_error}
    return rec, {"domain": dom, **answer}
