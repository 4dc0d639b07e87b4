"""Interpolated Cartesian motions: minimum-jerk straight lines, with fixed orientation or a
rotation about one axis."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_laws import CartesianTarget, orientation_error
from serpar.errors import ConfigError
from serpar.kinematics.rotations import so3_exp

Vec = NDArray[np.float64]


def min_jerk(s: float) -> tuple[float, float, float]:
    """Phase s in [0, 1] -> (position, velocity, acceleration) of the quintic 10s^3-15s^4+6s^5,
    derivatives per unit phase."""
    s = min(max(s, 0.0), 1.0)
    p = s**3 * (10 - 15 * s + 6 * s * s)
    v = 30 * s * s * (1 - s) ** 2
    a = 60 * s * (1 - s) * (1 - 2 * s)
    return p, v, a


@dataclass(frozen=True, eq=False)
class LineMove:
    """Straight TCP line from start to goal in `duration` seconds, orientation held at `rot`."""

    start: Vec
    goal: Vec
    rot: Vec
    duration: float

    def __post_init__(self) -> None:
        if not self.duration > 0:
            raise ConfigError(f"duration={self.duration} s must be > 0")

    def at(self, t: float) -> CartesianTarget:
        p, v, a = min_jerk(t / self.duration)
        delta = np.asarray(self.goal) - np.asarray(self.start)
        zeros = np.zeros(3)
        return CartesianTarget(self.start + p * delta, self.rot,
                               np.concatenate([v / self.duration * delta, zeros]),
                               np.concatenate([a / self.duration**2 * delta, zeros]))


@dataclass(frozen=True, eq=False)
class PoseMove:
    """Straight TCP line and a rotation about one fixed axis (the geodesic), both on the same
    minimum-jerk profile: the move ends at rest in position and orientation."""

    start: Vec
    goal: Vec
    start_rot: Vec
    goal_rot: Vec
    duration: float

    def __post_init__(self) -> None:
        if not self.duration > 0:
            raise ConfigError(f"duration={self.duration} s must be > 0")

    @cached_property
    def rotation_vector(self) -> Vec:
        """Rotation taking start_rot to goal_rot, in the base frame [rad] (computed once: `at`
        runs every control period)."""
        return orientation_error(self.start_rot, self.goal_rot)

    def at(self, t: float) -> CartesianTarget:
        p, v, a = min_jerk(t / self.duration)
        delta = np.asarray(self.goal) - np.asarray(self.start)
        turn = self.rotation_vector
        rot = so3_exp(p * turn) @ self.start_rot
        return CartesianTarget(self.start + p * delta, rot,
                               np.concatenate([v / self.duration * delta, v / self.duration * turn]),
                               np.concatenate([a / self.duration**2 * delta,
                                               a / self.duration**2 * turn]))
