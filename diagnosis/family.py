"""The contract between a data domain and the diagnosis engine.

A :class:`Family` knows how the nominal model predicts one recording and returns the
*whitened* residual (measured minus predicted, divided by the recording's noise sigma) for
any subset of rows, given the parameters of the always-fitted baseline and of whichever
candidate :class:`Effect` s are active. The engine (:mod:`serpar.diagnosis.select`) never
sees physics, only these residuals, so every domain (static arm measurements, arm time
series, Stewart legs, episodes) is diagnosed by the same staged functions.

Optional hook: a family whose domain has a model file of its own (the Stewart parameters
that ``serpar run`` reads) may define ``export(params, stem) -> list[Path]``, writing the
final fit's parameters (block name -> values) to files named ``<stem>.<what>``; see
:func:`export_model_files`. Families without it are untouched. Likewise
``residual_parts(rows, whitened) -> {name: entries}``: independent parts of the data (an
episode's arm channels and its chamfer slides) that selection tests against noise one by one
(:func:`serpar.diagnosis.forward.beyond_noise`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError


@dataclass(frozen=True)
class Effect:
    """One candidate piece of missing physics: a parametrised extension of the model."""

    name: str
    """Registry key used by ``serpar twin --effect``, e.g. ``"joint_compliance"``."""
    summary: str
    """Words for a user, e.g. ``"joint compliance (gravitational deflection)"``."""
    param_names: tuple[str, ...]
    units: tuple[str, ...]
    x0: NDArray[np.float64]
    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    physical_lower: bool | tuple[bool, ...] = False
    """The lower bound is a physical limit (no friction, no compliance, no clearance), so a
    parameter resting on it says "absent here"; every other bound only limits the search, and
    a parameter pinned on one means the candidate cannot be what the data show. One flag for
    all parameters, or one per parameter."""
    excess_words: str = ""
    """How to say a negative first parameter: something the nominal model has and the machine
    lacks (``"{value}"`` is replaced by its magnitude with unit), e.g. a payload of -0.7 kg."""
    fixed: tuple[int, ...] = ()
    """Parameters held at zero because the data do not identify them (:meth:`fix`)."""
    amplitude_of: tuple[int, ...] = ()
    """Per parameter, the index of the amplitude whose shape it sets (-1: none; empty: no
    parameter is a shape), e.g. a joint's Stribeck speed is the shape of its Stribeck excess:
    with no amplitude on that joint the shape is not identified, and both are held
    (diagnosis/stability.py's ``fit_identified``)."""

    def __post_init__(self) -> None:
        if not self.name:
            raise IdentificationError("Effect.name must be a non-empty string")
        n = len(self.param_names)
        for field in ("units", "x0", "lower", "upper"):
            if len(getattr(self, field)) != n:
                raise IdentificationError(
                    f"Effect {self.name!r}: {field} has {len(getattr(self, field))} entries, "
                    f"param_names has {n}"
                )
        if len(set(self.param_names)) != n:
            raise IdentificationError(f"Effect {self.name!r}: parameter names repeat")
        # Store float arrays (frozen dataclass: object.__setattr__ is the sanctioned way).
        for field in ("x0", "lower", "upper"):
            object.__setattr__(self, field, np.asarray(getattr(self, field), dtype=np.float64))
        if not np.all(np.isfinite(self.x0)):
            raise IdentificationError(f"Effect {self.name!r}: x0 must be finite")
        if np.any(self.lower > self.upper):
            raise IdentificationError(f"Effect {self.name!r}: lower bound above upper bound")
        if np.any(self.x0 < self.lower) or np.any(self.x0 > self.upper):
            raise IdentificationError(f"Effect {self.name!r}: x0 lies outside [lower, upper]")
        if self.amplitude_of and (len(self.amplitude_of) != n
                                  or any(not -1 <= a < n for a in self.amplitude_of)):
            raise IdentificationError(f"Effect {self.name!r}: amplitude_of needs {n} indices "
                                      "in -1..n-1")
        if not isinstance(self.physical_lower, bool) and len(self.physical_lower) != n:
            raise IdentificationError(f"Effect {self.name!r}: physical_lower has "
                                      f"{len(self.physical_lower)} flags, param_names has {n}")

    @property
    def physical_lower_mask(self) -> NDArray[np.bool_]:
        """Per parameter: is its lower bound a physical limit?"""
        if isinstance(self.physical_lower, bool):
            return np.full(self.n_params, self.physical_lower)
        return np.array(self.physical_lower, bool)

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    def restricted(self, keep: NDArray[np.int64]) -> Effect:
        """The same effect with only the parameters ``keep`` (indices into param_names)."""
        where = {int(i): k for k, i in enumerate(keep)}
        amplitude_of = (tuple(where.get(self.amplitude_of[i], -1) for i in keep)
                        if self.amplitude_of else ())
        return replace(self, param_names=tuple(self.param_names[i] for i in keep),
                       amplitude_of=amplitude_of,
                       units=tuple(self.units[i] for i in keep), x0=self.x0[keep],
                       lower=self.lower[keep], upper=self.upper[keep],
                       physical_lower=(self.physical_lower if isinstance(self.physical_lower, bool)
                                       else tuple(self.physical_lower[i] for i in keep)))

    def pinned(self, values: NDArray[np.float64], rel_tol: float = 1e-3) -> list[int]:
        """Indices of the parameters that sit on a search bound (not a physical limit)."""
        span = np.maximum(self.upper - self.lower, 1e-300)
        at_lo = (values - self.lower) <= rel_tol * span
        at_hi = (self.upper - values) <= rel_tol * span
        at_lo[self.physical_lower_mask] = False
        free = np.ones(self.n_params, bool)
        free[list(self.fixed)] = False
        return [int(i) for i in np.flatnonzero((at_lo | at_hi) & free)]

    def shapes_of(self, amplitude: int) -> list[int]:
        """The parameters whose shape ``amplitude`` scales."""
        return [i for i, a in enumerate(self.amplitude_of) if a == amplitude]

    def fix(self, indices: list[int]) -> Effect:
        """The same effect with the parameters ``indices`` held at zero (the fit leaves them
        out of its search)."""
        return replace(self, fixed=tuple(sorted(set(self.fixed) | set(indices))))


@dataclass(frozen=True)
class LocateRow:
    """One line of the "where" table."""

    channel: str
    """e.g. ``"q4"``, ``"tool x"``, ``"socket 2"``."""
    group: str
    """What the residual is split by: ``"phase"``, ``"region"``, ``"regime"``, ``"time"``..."""
    label: str
    """e.g. ``"insert"``, ``"high gravity load"``, ``"velocity reversal"``, ``"t>10 s"``."""
    n: int
    rms_whitened: float
    """RMS of residual/sigma; about 1 when the model explains the data to noise."""
    p_value: float
    """Chi-square test of the whitened residual against unit-variance noise."""
    flagged: bool

    def as_dict(self) -> dict[str, object]:
        return {
            "channel": self.channel,
            "group": self.group,
            "label": self.label,
            "n": int(self.n),
            "rms_whitened": float(self.rms_whitened),
            "p_value": float(self.p_value),
            "flagged": bool(self.flagged),
        }


@runtime_checkable
class Family(Protocol):
    """One data domain: how the nominal model predicts this recording."""

    kind: str
    baseline: Effect | None
    """Fitted always (e.g. unknown socket points, tool offset, tares)."""
    effects: tuple[Effect, ...]
    """The candidate library applicable to this recording."""
    n_samples: int
    """Rows that :meth:`residual` can select among."""

    def residual(
        self, params: Mapping[str, NDArray[np.float64]], rows: NDArray[np.int64]
    ) -> NDArray[np.float64]:
        """Whitened residual (divided by the recording's noise sigma) of the given rows, given
        the parameters of the baseline and of every *active* effect (absent key = effect not
        active)."""
        ...

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Train rows, held-out rows: held-out must be configurations / time segments the fit
        never sees."""
        ...

    def locate(self, rows: NDArray[np.int64], whitened: NDArray[np.float64]) -> list[LocateRow]:
        """The "where" table of the given rows' whitened residual."""
        ...

    # Optional (diagnosis/fit.py looks for them): ``jacobian(params, rows)``, the residual's
    # derivative by every parameter, columns in the mapping's block order, else 2-point
    # differences; with ``baseline_columns(params, rows)`` (the baseline's, sparse) the fit
    # solves the baseline out (diagnosis/separable.py) and calls ``jacobian(params, rows,
    # skip=(baseline,))``, the columns of the blocks in ``skip`` left out.


def export_model_files(family: object, model: Mapping[str, object], stem: Path) -> list[Path]:
    """The family's own model files for the final fit (``model``: ``Diagnosis.model``), or
    none when the family has no ``export`` hook. A wrapper that keeps its family as ``inner``
    (diagnosis/prior.py) exports through it: ``model`` is then the combined one."""
    hook = getattr(family, "export", None) or getattr(getattr(family, "inner", None), "export", None)
    if not callable(hook):
        return []
    blocks = model.get("params", {})
    params = {name: np.asarray(block["values"], float)  # type: ignore[index]
              for name, block in blocks.items()}  # type: ignore[union-attr]
    return [Path(p) for p in hook(params, stem)]
