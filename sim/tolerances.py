"""ISO fit tolerance bands and seeded draws of actual part diameters (seed 000 Table 1).

Every hole and every journal gets an actual diameter inside its band, so the
diametral clearance of a pair lies in 0..16 um as on real H7/h6 parts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from serpar.errors import ConfigError

Distribution = Literal["uniform", "normal"]
DISTRIBUTIONS: tuple[str, ...] = ("uniform", "normal")


@dataclass(frozen=True)
class ToleranceBand:
    """A nominal size with lower/upper deviations [m]."""

    nominal: float
    lower: float
    upper: float

    def __post_init__(self) -> None:
        if self.nominal <= 0 or self.upper < self.lower:
            raise ConfigError(f"bad tolerance band {self}: need nominal > 0 and upper >= lower")

    @property
    def min(self) -> float:
        return self.nominal + self.lower

    @property
    def max(self) -> float:
        return self.nominal + self.upper

    def draw(self, rng: np.random.Generator, n: int, distribution: Distribution) -> np.ndarray:
        """Actual sizes of n parts. 'normal' is centred with 3 sigma at the band edges, clipped."""
        if distribution == "uniform":
            return rng.uniform(self.min, self.max, n)
        if distribution == "normal":
            mid, sigma = 0.5 * (self.min + self.max), (self.max - self.min) / 6.0
            return np.clip(rng.normal(mid, sigma, n), self.min, self.max)
        raise ConfigError(f"unknown distribution {distribution!r}; valid: {', '.join(DISTRIBUTIONS)}")


HOLE_H7 = ToleranceBand(1.700e-3, 0.0, 10e-6)
"""Baseplate hole, Ø1.700 H7 (+0.010/0 mm)."""
JOURNAL_H6 = ToleranceBand(1.700e-3, -6e-6, 0.0)
"""Conductor journal, Ø1.700 h6 (0/-0.006 mm)."""
BODY_H6 = ToleranceBand(5.000e-3, -8e-6, 0.0)
"""Conductor body, Ø5.0 (0/-0.008 mm)."""


@dataclass(frozen=True)
class DrawnDiameters:
    """Actual diameters [m] of every hole (row-major) and every conductor of one scene."""

    holes: tuple[float, ...]
    journals: tuple[float, ...]
    bodies: tuple[float, ...]

    def clearance(self, hole: int, conductor: int) -> float:
        """Diametral clearance [m] of a hole/journal pair (>= 0 for H7/h6)."""
        return self.holes[hole] - self.journals[conductor]


def draw_diameters(
    seed: int, n_holes: int, n_conductors: int, distribution: Distribution = "uniform"
) -> DrawnDiameters:
    """Seeded draw of all actual diameters of a scene; same seed, same parts."""
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool):
        raise ConfigError(f"seed must be an integer, got {seed!r}")
    rng = np.random.default_rng(seed)
    holes = HOLE_H7.draw(rng, n_holes, distribution)
    journals = JOURNAL_H6.draw(rng, n_conductors, distribution)
    bodies = BODY_H6.draw(rng, n_conductors, distribution)
    return DrawnDiameters(tuple(map(float, holes)), tuple(map(float, journals)), tuple(map(float, bodies)))
