"""The three measurement types of an arm calibration campaign (DESIGN.md §4 ``measurements``),
validated on construction so a bad campaign fails with one line that says what is wrong.

- :class:`PositionSet`: the tool point seen by a laser tracker at each pose (seed 003 §7).
- :class:`PoseSet`: the full tool pose (position and orientation) at each pose.
- :class:`PointSet`: point consistency: many poses put the tool point in the same unknown
  socket; some sockets are a known distance apart (the real ``panda_1`` data).

Every set carries the commanded joint angles (what the encoders report) and, for the
gravity-aware model, the gravity torques a nominal dynamic model gives at those angles (the
controller's own gravity model, like libfranka's ``gravity()``; never the plant's truth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.kinematics.robot import PANDA, Robot

JOINT_LIMIT_TOL = 1e-3
"""Joint angles may exceed the datasheet range by this much [rad] (encoder resolution)."""
MAX_TOOL_RADIUS_M = 2.0
"""A measured point farther than this from the base frame is in the wrong unit or frame."""


def _array(name: str, value: object, shape: tuple[int, ...]) -> NDArray[np.float64]:
    a = np.asarray(value, dtype=float)
    if a.shape != shape:
        raise IdentificationError(f"{name} has shape {a.shape}, expected {shape}")
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        raise IdentificationError(f"{name} contains NaN or infinite values "
                                  f"(first at pose {int(bad[0][0])})")
    return a


def _check_joints(q: object, tau: object | None, robot: Robot) -> int:
    if not isinstance(robot, Robot):
        raise IdentificationError("a measurement set's robot must be an "
                                  "serpar.kinematics.robot.Robot (default: the Panda)")
    a = np.asarray(q, dtype=float)
    n_j = robot.n_joints
    if a.ndim != 2 or a.shape[1] != n_j:
        raise IdentificationError(f"q has shape {a.shape}, expected (N, {n_j}) joint angles "
                                  f"of {robot.label}")
    n = a.shape[0]
    if n == 0:
        raise IdentificationError("the measurement set has no poses")
    a = _array("q", a, (n, n_j))
    q_min, q_max = robot.q_min, robot.q_max
    lo, hi = np.asarray(q_min) - JOINT_LIMIT_TOL, np.asarray(q_max) + JOINT_LIMIT_TOL
    out = np.argwhere((a < lo) | (a > hi))
    if out.size:
        k, j = (int(v) for v in out[0])
        raise IdentificationError(
            f"q of pose {k}: joint {j + 1} at {a[k, j]:.4f} rad is outside its range "
            f"{q_min[j]:.4g}..{q_max[j]:.4g} rad of {robot.label} ({len(out)} value(s) out of "
            f"range; radians expected{robot.other_arm_hint})")
    if tau is not None:
        _array("tau_gravity", tau, (n, n_j))
    return n


def _check_points(name: str, p: object, n: int) -> None:
    a = _array(name, p, (n, 3))
    far = np.flatnonzero(np.linalg.norm(a, axis=1) > MAX_TOOL_RADIUS_M)
    if far.size:
        raise IdentificationError(
            f"{name} of pose {int(far[0])} is {np.linalg.norm(a[far[0]]):.3g} m from the base "
            f"frame, beyond any reach ({MAX_TOOL_RADIUS_M} m); metres in the base frame expected")


def _check_sigma(**sigmas: float) -> None:
    for name, s in sigmas.items():
        if not (np.isfinite(s) and s > 0):
            raise IdentificationError(f"{name} must be a positive noise level, got {s!r}")


@dataclass(frozen=True)
class PositionSet:
    """Tool-point positions [m, base frame] measured by a laser tracker."""

    q: NDArray[np.float64]
    position: NDArray[np.float64]
    sigma: float = 15e-6
    """Tracker noise per axis [m] (Leica AT901-B, seed 003 §7.1)."""
    tau_gravity: NDArray[np.float64] | None = None
    robot: Robot = PANDA
    """The arm whose joint count and limits the angles are checked against."""

    def __post_init__(self) -> None:
        n = _check_joints(self.q, self.tau_gravity, self.robot)
        _check_points("position", self.position, n)
        _check_sigma(sigma=self.sigma)

    @property
    def n_poses(self) -> int:
        return len(self.q)


@dataclass(frozen=True)
class PoseSet:
    """Full tool poses: positions [m] and rotation matrices, base frame."""

    q: NDArray[np.float64]
    position: NDArray[np.float64]
    rotation: NDArray[np.float64]
    sigma: float = 15e-6
    sigma_rotation: float = 50e-6
    """Orientation noise per axis [rad]."""
    tau_gravity: NDArray[np.float64] | None = None
    robot: Robot = PANDA
    """The arm whose joint count and limits the angles are checked against."""

    def __post_init__(self) -> None:
        n = _check_joints(self.q, self.tau_gravity, self.robot)
        _check_points("position", self.position, n)
        r = _array("rotation", self.rotation, (n, 3, 3))
        ortho = np.abs(r @ r.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero((ortho > 1e-6) | (np.linalg.det(r) < 0))
        if bad.size:
            raise IdentificationError(f"rotation of pose {int(bad[0])} is not a rotation matrix")
        _check_sigma(sigma=self.sigma, sigma_rotation=self.sigma_rotation)

    @property
    def n_poses(self) -> int:
        return len(self.q)


@dataclass(frozen=True)
class PointSet:
    """Point consistency: pose k seats the tool point in socket ``point[k]`` (unknown centre);
    ``distances`` lists (socket i, socket j, centre distance [m]) known from the fixture."""

    q: NDArray[np.float64]
    point: NDArray[np.int64]
    distances: tuple[tuple[int, int, float], ...] = ()
    sigma: float = 50e-6
    """Seating repeatability of the ball in a socket, per axis [m]."""
    sigma_distance: float = 50e-6
    """Uncertainty of a fixture distance [m]."""
    tau_gravity: NDArray[np.float64] | None = None
    robot: Robot = PANDA
    """The arm whose joint count and limits the angles are checked against."""

    def __post_init__(self) -> None:
        n = _check_joints(self.q, self.tau_gravity, self.robot)
        ids = np.asarray(self.point)
        if ids.shape != (n,) or not np.issubdtype(ids.dtype, np.integer):
            raise IdentificationError(f"point must be {n} integer socket ids, got shape "
                                      f"{ids.shape} of {ids.dtype}")
        if ids.min() < 0 or set(np.unique(ids)) != set(range(int(ids.max()) + 1)):
            raise IdentificationError("socket ids must be 0..P-1 with every socket used; got "
                                      f"{sorted(set(ids.tolist()))}")
        for i, j, dist in self.distances:
            if not (0 <= i < self.n_points and 0 <= j < self.n_points and i != j):
                raise IdentificationError(f"distance ({i}, {j}) names sockets outside "
                                          f"0..{self.n_points - 1} or twice the same one")
            if not (np.isfinite(dist) and dist > 0):
                raise IdentificationError(f"distance between sockets {i} and {j} must be a "
                                          f"positive length [m], got {dist!r}")
        _check_sigma(sigma=self.sigma, sigma_distance=self.sigma_distance)

    @property
    def n_poses(self) -> int:
        return len(self.q)

    @property
    def n_points(self) -> int:
        return int(np.max(self.point)) + 1


Measurements = PositionSet | PoseSet | PointSet
