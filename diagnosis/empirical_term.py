"""The empirical term's pieces (diagnosis/empirical.py selects them): a basis group tied to one
residual channel, variable and shape; a kept term with its coefficients and words; the whole
term with its held-out figures. Its words name a hypothesis, never a library effect."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]


Refit = Callable[[list[int]], tuple[Vec, Vec, Vec]]
"""chosen group indices -> (training residual, held-out residual, coefficients) of the model
refitted together with those groups."""


@dataclass(frozen=True)
class Tuning:
    """A group's continuous shape parameter (a transition speed, a time constant): the library
    offers it on a grid, and a selected group is refined to the value the training rows fit
    best (:func:`serpar.diagnosis.empirical.tune`) within bounds set by the physics."""

    name: str
    """Its key in the group's ``detail``."""
    low: float
    high: float
    at: Callable[[float], BasisGroup]
    """The same group (channel, variable, shape) with the parameter at another value."""


@dataclass(frozen=True)
class RestBand:
    """A friction holds a joint at rest anywhere within the level it has as motion starts: the
    residual of a row where the joint may be stuck lies unexplained within the band
    ``weight(rows) x max(level, 0)``, ``level`` = sum over the channel's friction groups of
    ``onset @ coefficients`` (a term that cancels a fall's level in motion cancels its band)."""

    weight: Callable[[Rows], Vec]
    """(rows,) the window's share of samples where the joint may be stuck, over sigma."""
    onset: tuple[float, ...]
    """The odd part of each column at the stick velocity."""


@dataclass(frozen=True)
class BasisGroup:
    """Basis columns that enter or leave the empirical term together."""

    channel: str
    """The residual channel it acts on, e.g. ``"tau_J_d4"``, ``"leg 3"``."""
    variable: str
    """What it follows, e.g. ``"q4"``, ``"dq2"``, ``"time"``, ``"stroke 3"``."""
    shape: str
    """One of :data:`SHAPES`' keys."""
    label: str
    """The basis in symbols, e.g. ``"sin, cos(2 pi q4 / 25.7 deg)"``."""
    unit: str
    """Unit of a coefficient."""
    columns: Callable[[Rows], Vec]
    """Whitened: (rows, k) values at the given rows for a channel-local group (``column``
    set), or (rows x channels, k) over the whole whitened residual (``column`` None)."""
    physical: Callable[[Rows], Vec]
    """(rows, k) the basis in the channel's physical unit at the given rows: the term is
    ``physical(rows) @ coefficients`` there (what a model file carries)."""
    column: int | None = None
    """Index of the residual channel (within a row) a channel-local group acts on."""
    detail: Mapping[str, float] = field(default_factory=dict)
    """Numbers its words use (a period [deg], a time constant [s], ...)."""
    tuning: Tuning | None = None
    """Its continuous shape parameter, where it has one (None: the group is fixed)."""
    rest: RestBand | None = None
    """Where it is a friction against motion: how it holds the joint at rest (None: not a
    friction)."""
    beside: Callable[[Rows], Vec] | None = None
    """Whitened columns, laid out like ``columns``, of what a library candidate may already
    hold of it (a misread angle's constant part: an encoder offset). Screening scores the
    group by what it adds beside them, since the model refitted with it moves those back."""

    @property
    def width(self) -> int:
        """Number of its columns (coefficients)."""
        return int(np.asarray(self.physical(np.zeros(1, np.int64))).shape[1])

    @property
    def key(self) -> tuple[str, str, str]:
        return self.channel, self.variable, self.shape


SHAPES: dict[str, str] = {
    "periodic": "periodic in {variable}, period {period_deg:.3g} deg, amplitude {amplitude}: looks "
                "like transmission ripple (gear meshing, motor cogging)",
    "reversal step": "a step of {step} at each reversal of {variable}: dry friction acting in "
                     "this channel",
    "smooth step": "a smooth step of {step} through each reversal of {variable} (over ~{speed:.2g} "
                   "/s), {level} higher one way than the other: friction that passes through "
                   "zero at rest smoothly, about an offset (a sigmoid)",
    "stribeck": "a force opposing motion that falls from {amplitude} at standstill as {variable} "
                "grows (~{speed:.2g} /s): friction that is higher near standstill (Stribeck)",
    "stribeck along": "a force along the motion, largest near standstill ({amplitude}), that "
                      "fades as {variable} grows (~{speed:.2g} /s): not a friction (a friction "
                      "opposes motion)",
    "proportional": "off by {coefficient} x {variable} ({amplitude} RMS): a scale error "
                    "(encoder, screw lead or gear ratio)",
    "drift": "a drift with time, {amplitude} over the recording ({profile}): thermal growth or "
             "a sensor drift",
}


def design(groups: list[BasisGroup], chosen: list[int], rows: Rows, n_channels: int,
           cache: dict[tuple[int, int], Vec] | None = None) -> Vec:
    """(rows x channels, sum k) whitened columns of the chosen groups over the whole residual."""
    cache = {} if cache is None else cache
    blocks: list[Vec] = []
    for g in chosen:
        x = columns_at(groups[g], rows, cache)
        if groups[g].column is None:
            blocks.append(x)
        else:
            full = np.zeros((len(rows), n_channels, x.shape[1]))
            full[:, groups[g].column, :] = x
            blocks.append(full.reshape(len(rows) * n_channels, -1))
    return np.hstack(blocks) if blocks else np.zeros((len(rows) * n_channels, 0))


def columns_at(group: BasisGroup, rows: Rows, cache: dict[tuple[int, int], Vec] | None = None
               ) -> Vec:
    """(rows, k) a channel-local group's whitened columns, or (rows x channels, k) a group's
    over the whole residual; ``cache`` keeps them per (group, rows) object."""
    if cache is None:
        cache = {}
    key = (id(group), id(rows))
    if key not in cache:
        x = np.asarray(group.columns(rows), float)
        cache[key] = x.reshape(len(rows) if group.column is not None else x.shape[0], -1)
    return cache[key]


@dataclass(frozen=True)
class Term:
    group: BasisGroup
    coefficients: Vec
    """Physical units, one per column."""
    heldout_drop: float
    """Held-out chi-square removed when it entered."""
    frequency: float
    """Share of the resampled folds on which it held up (material, acting the same way)."""
    size: float
    """Its size over all rows [unit of the channel]: the range a drift covers, else the RMS
    of its contribution."""

    def words(self) -> str:
        g = self.group
        amp = f"{self.size * np.sqrt(2.0) if g.shape == 'periodic' else self.size:.2g} {g.unit}"
        # a fall whose coefficient is negative acts along the motion: not a friction
        shape = "stribeck along" if g.shape == "stribeck" and self.coefficients[0] < 0 else g.shape
        text = SHAPES[shape].format(
            variable=g.variable, amplitude=amp, coefficient=f"{self.coefficients[0]:.3g}", step=f"{2 * abs(self.coefficients[0]):.2g} {g.unit}",
            level=f"{2 * abs(self.coefficients[-1]):.2g} {g.unit}",
            period_deg=g.detail.get("period_deg", 0.0), speed=g.detail.get("speed", 0.0),
            profile=g.label)
        return f"{g.channel} {text}; not in the library"

    def as_dict(self) -> dict[str, object]:
        g = self.group
        return {"channel": g.channel, "variable": g.variable, "shape": g.shape, "basis": g.label,
                "unit": g.unit, "coefficients": [float(c) for c in self.coefficients],
                "detail": {k: float(v) for k, v in g.detail.items()},
                "heldout_chi2_drop": self.heldout_drop, "resampled_frequency": self.frequency,
                "size": self.size, "hypothesis": self.words()}


@dataclass(frozen=True)
class EmpiricalTerm:
    terms: tuple[Term, ...]
    heldout_rms_before: float
    heldout_rms_after: float
    """Held-out whitened RMS with the kept terms added (1 = the stated noise)."""
    rejected: tuple[str, ...] = ()
    """Groups the main split selected that did not hold up on the folds, with on how many
    they did."""

    def words(self) -> str:
        if not self.terms:
            return "no empirical term holds up on held-out data and resampled folds"
        return ("; ".join(t.words() for t in self.terms)
                + f" (held-out {self.heldout_rms_before:.3g} -> {self.heldout_rms_after:.3g} "
                  "x the stated noise with this empirical term)")

    def as_dict(self) -> dict[str, object]:
        return {"terms": [t.as_dict() for t in self.terms],
                "heldout_rms_whitened_before": self.heldout_rms_before,
                "heldout_rms_whitened_after": self.heldout_rms_after,
                "rejected": list(self.rejected), "words": self.words()}
