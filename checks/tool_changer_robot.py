"""The shield-machine tool-changing robot of seed 001, its error distributions and their
samplers, the paper's reference figures, and :class:`ArmModel`, the arm description the error
analysis works on.

Every number is read off ``../shared/seeds/001_39ba755d515b53ae.txt`` and cites its place. The
paper's results (Tables 3 and 5, Eq. 26) appear only as reference values printed beside
serpar's own Monte Carlo, never as inputs.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from serpar.errors import ConfigError, IdentificationError
from serpar.kinematics import poe

Array = NDArray[np.float64]
Geometry = Callable[[Array], tuple[Array, Array, Array]]

LENGTH_NAMES: tuple[str, ...] = ("l1", "l2", "l3", "l4", "l5", "l6")
JOINT_NAMES: tuple[str, ...] = ("theta1", "theta2", "theta3", "d4", "theta5", "theta6")
PRISMATIC: tuple[bool, ...] = (False, False, False, True, False, False)
"""Five revolute joints and the telescopic arm, joint 4 ("Clearance error modelling", 1st para)."""

LINK_LENGTHS_M: tuple[float, ...] = (0.315, 0.210, 0.796, 0.560, 0.240, 0.165)
"""Table 2, "Mean value of linkage length" [mm], in m."""
LINK_SIGMA_M: tuple[float, ...] = (0.17e-3, 0.15e-3, 0.2e-3, 0.25e-3, 0.15e-3, 0.15e-3)
"""Table 2, "Standard deviation of linkage length error"."""

_DEG = math.pi / 180
JOINT_Q: tuple[float, ...] = (15 * _DEG, 30 * _DEG, -10 * _DEG, 0.0, -20 * _DEG, 0.0)
"""Table 2, "Mean value of motion" (rad, joint 4 in m). Table 2 has no row for joint 6: 0 is
assumed; it turns about the vertical axis through the tool point, so only orientation sees it."""
JOINT_SIGMA: tuple[float, ...] = (0.3 * _DEG, 0.3 * _DEG, 0.1548 * _DEG, 0.25e-3, 0.5 * _DEG,
                                  0.0087)
"""Table 2, "Standard deviation of motion error"; joint 6 (missing row) takes Table 1's 0.0087."""

# Table 1, "The distribution of each error": all normal with zero mean.
TABLE1_LINK_SIGMA_M = 0.2e-3
TABLE1_PRISMATIC_SIGMA_M = 0.3e-3
TABLE1_REVOLUTE_SIGMA_RAD = 0.0087
TABLE1_DEFLECTION_SIGMA_RAD = 0.00435

# Table 4, "Kinematics parameter values of joint clearance": normal, zero mean; the radial
# direction theta_i is uniform on [0, 2 pi] (text under Eq. 43).
TABLE4_AXIAL_SIGMA_M = 0.2e-3
TABLE4_RADIAL_SIGMA_M = 0.5e-3
TABLE4_DEFLECTION_SIGMA_RAD = 0.087

_X, _Y, _Z = np.eye(3)
AXES = np.array([_Z, _X, _X, _Y, _X, _Z])
"""Eq. 34: w1 = w6 = z, w2 = w3 = w5 = x; the telescopic joint 4 slides along the arm, +y
(Eq. 24 grows y with l3..l6)."""

PAPER_SAMPLES = 20_000
"""Monte Carlo size, "Simulation analysis" of the transmission errors."""
PAPER_IDEAL_POSITION = (-0.0924, 0.1609, -1.5119)
"""Ideal end position as printed under Table 2 (no unit given)."""
PAPER_TABLE3: dict[str, tuple[float, float, float, float]] = {
    "dp": (0.0112, 0.1105, 0.4754, -0.3804),
    "dx": (-4.71e-5, 0.1389, 0.5672, -0.6406),
    "dy": (1.59e-4, 0.0822, 0.2991, -0.3574),
    "dz": (2.54e-4, 0.1414, 0.5389, -0.6547),
}
"""Table 3: (mean, std, max, min) of the end position error [mm], Table 1/2 errors."""
PAPER_TABLE5: dict[str, tuple[float, float, float, float]] = {
    "dp": (-0.2669, 0.4281, 1.557, -1.3677),
    "dx": (1.0033, 0.4835, 2.9457, -0.8082),
    "dy": (5.1599e-04, 0.2985, 1.0452, -1.0669),
    "dz": (-9.0025e-04, 0.3853, 1.3884, -1.3202),
    "dphi": (-9.9408e-07, 2.1801e-04, 9.5873e-04, -9.3875e-04),
    "dtheta": (6.8450e-07, 1.5260e-04, 6.5689e-04, -6.7131e-04),
    "dpsi": (2.9981e-07, 6.9772e-05, 3.0010e-04, -3.0719e-04),
}
"""Table 5: (mean, std, max, min) of the end error under joint clearance [mm, rad]."""
PAPER_POSITION_RELIABILITY: dict[float, float] = {0.15: 0.7639, 0.25: 0.9503}
"""Eq. 26: P(|dP| < T) for T [mm]."""
PAPER_ANGLE_THRESHOLD_RAD = 0.002
PAPER_ANGLE_RELIABILITY: tuple[float, float, float] = (0.7639, 0.8458, 0.9855)
"""Eq. 26: P(|d angle| < 0.002 rad) for the three Euler angles (the first equals the 0.15 mm
position figure, probably a copy slip in the paper)."""


def seed001_geometry(lengths: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64],
                                                   NDArray[np.float64]]:
    """Axes, axis points (Eq. 24) and tool pose T(0) (Eq. 23) for link lengths (..., 6) [m].

    r1 = (0, 0, l1), r2 = (0, 0, l1+l2), r_k = (0, l3+..+l_{k-1}+.., l1+l2); the tool sits on
    the joint-6 axis at (0, l3+l4+l5+l6, l1+l2) with the base orientation. Eq. 24's r6 prints
    "l5 + dl6" for l6 + dl6, read as the latter.
    """
    ln = np.asarray(lengths, dtype=float)
    zero = np.zeros(ln.shape[:-1])
    h1, h2 = ln[..., 0], ln[..., 0] + ln[..., 1]
    reach = np.cumsum(ln[..., 2:], axis=-1)
    ys = [zero, zero, ln[..., 2], reach[..., 1], reach[..., 2], reach[..., 3]]
    zs = [h1, h2, h2, h2, h2, h2]
    points = np.stack([np.stack([zero, y, z], -1) for y, z in zip(ys, zs)], -2)
    home = np.broadcast_to(np.eye(4), ln.shape[:-1] + (4, 4)).copy()
    home[..., :3, 3] = points[..., -1, :]
    axes = np.broadcast_to(AXES, points.shape).copy()
    return axes, points, home


def _check_sigmas(name: str, values: tuple[float, ...]) -> None:
    if not all(math.isfinite(v) and v >= 0 for v in values):
        raise ConfigError(f"{name} {values}: standard deviations must be finite and >= 0")


@dataclass(frozen=True)
class TransmissionErrors:
    """Normal, zero-mean link, drive and axis-deflection errors (Tables 1-2)."""

    link_sigma_m: tuple[float, ...]
    drive_sigma: tuple[float, ...]
    """Per joint: rad (revolute) or m (prismatic)."""
    deflection_sigma_rad: float
    """Each of the two deflection angles of every joint axis (Table 1 gives one sigma; serpar
    draws both perpendicular directions of Eq. 35 with it)."""

    def __post_init__(self) -> None:
        _check_sigmas("link_sigma_m", self.link_sigma_m)
        _check_sigmas("drive_sigma", self.drive_sigma)
        _check_sigmas("deflection_sigma_rad", (self.deflection_sigma_rad,))


@dataclass(frozen=True)
class ClearanceErrors:
    """Joint clearance of every revolute joint (Table 4)."""

    axial_sigma_m: float = TABLE4_AXIAL_SIGMA_M
    radial_sigma_m: float = TABLE4_RADIAL_SIGMA_M
    deflection_sigma_rad: float = TABLE4_DEFLECTION_SIGMA_RAD

    def __post_init__(self) -> None:
        _check_sigmas("clearance", (self.axial_sigma_m, self.radial_sigma_m,
                                    self.deflection_sigma_rad))


def table2_errors() -> TransmissionErrors:
    """Table 2's per-link and per-joint sigmas of this robot, Table 1's axis deflection."""
    return TransmissionErrors(LINK_SIGMA_M, JOINT_SIGMA, TABLE1_DEFLECTION_SIGMA_RAD)


def table1_errors(n_links: int, prismatic: Sequence[bool]) -> TransmissionErrors:
    """Table 1's per-type sigmas for any arm: every link, every prismatic or revolute drive."""
    drive = tuple(TABLE1_PRISMATIC_SIGMA_M if p else TABLE1_REVOLUTE_SIGMA_RAD for p in prismatic)
    return TransmissionErrors((TABLE1_LINK_SIGMA_M,) * n_links, drive, TABLE1_DEFLECTION_SIGMA_RAD)


@dataclass(frozen=True)
class ArmModel:
    """A serial arm as the error analysis sees it: named link lengths, joints, a geometry map.

    geometry(lengths (..., L)) -> joint axes (..., n, 3), axis points (..., n, 3) and the tool
    pose M (..., 4, 4) at the zero configuration, all in the base frame [m].
    """

    name: str
    length_names: tuple[str, ...]
    lengths_m: tuple[float, ...]
    joint_names: tuple[str, ...]
    prismatic: tuple[bool, ...]
    q: tuple[float, ...]
    geometry: Geometry = field(repr=False)

    def __post_init__(self) -> None:
        if len(self.length_names) != len(self.lengths_m):
            raise IdentificationError(f"{self.name}: {len(self.length_names)} length names for "
                                      f"{len(self.lengths_m)} lengths")
        if not len(self.joint_names) == len(self.prismatic) == len(self.q):
            raise IdentificationError(f"{self.name}: joint names, types and q differ in length")

    def nominal(self) -> tuple[Array, Array]:
        """Joint twists (n, 6) and tool pose M (4, 4) of the error-free arm."""
        axes, points, home = self.geometry(np.asarray(self.lengths_m))
        return poe.twist(axes, points, self.prismatic), home

    def tool_pose(self) -> Array:
        """Error-free tool pose at the working configuration q (4, 4)."""
        twists, home = self.nominal()
        return poe.forward_kinematics(twists, self.q, home)


def seed001_model() -> ArmModel:
    """The tool-changing robot of Table 2 at its working configuration."""
    return ArmModel("seed001", LENGTH_NAMES, LINK_LENGTHS_M, JOINT_NAMES, PRISMATIC, JOINT_Q,
                    seed001_geometry)


@dataclass(frozen=True)
class ErrorSample:
    """One batch of sampled errors, N robots; zeros where an error source is off."""

    dl: Array
    """(N, L) link length errors [m]."""
    dq: Array
    """(N, n) drive errors [rad or m]."""
    deflection: Array
    """(N, n, 2) axis deflections about the two perpendicular axes u, v [rad]."""
    axial: Array
    """(N, n) axial clearance movement [m]."""
    radial: Array
    """(N, n, 2) radial clearance movement along u, v [m]."""


def sample_transmission(model: ArmModel, errors: TransmissionErrors, n: int,
                        rng: np.random.Generator) -> ErrorSample:
    """Draw n robots with Table 1/2 errors."""
    nl, nj = len(model.lengths_m), len(model.q)
    if len(errors.link_sigma_m) != nl or len(errors.drive_sigma) != nj:
        raise IdentificationError(f"{model.name} has {nl} links and {nj} joints; got "
                                  f"{len(errors.link_sigma_m)} link and "
                                  f"{len(errors.drive_sigma)} drive sigmas")
    return ErrorSample(rng.normal(size=(n, nl)) * errors.link_sigma_m,
                       rng.normal(size=(n, nj)) * errors.drive_sigma,
                       rng.normal(size=(n, nj, 2)) * errors.deflection_sigma_rad,
                       np.zeros((n, nj)), np.zeros((n, nj, 2)))


def sample_clearance(model: ArmModel, errors: ClearanceErrors, n: int,
                     rng: np.random.Generator) -> ErrorSample:
    """Draw n robots with Table 4 clearance at every revolute joint (Eq. 36: n = 1, 2, 3, 5, 6)."""
    nl, nj = len(model.lengths_m), len(model.q)
    rev = ~np.asarray(model.prismatic)
    rod = rng.normal(size=(n, nj)) * errors.radial_sigma_m
    angle = rng.uniform(0.0, 2 * np.pi, size=(n, nj))
    return ErrorSample(np.zeros((n, nl)), np.zeros((n, nj)),
                       rng.normal(size=(n, nj, 2)) * errors.deflection_sigma_rad * rev[:, None],
                       rng.normal(size=(n, nj)) * errors.axial_sigma_m * rev,
                       np.stack([rod * np.cos(angle), rod * np.sin(angle)], -1) * rev[:, None])
