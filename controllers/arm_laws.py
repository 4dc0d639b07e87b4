"""What the arm control laws take besides the model: their gains and targets, and the TCP
orientation error by MuJoCo's own quaternion functions.

The laws themselves are pure functions over a leading batch axis in
:mod:`serpar.controllers.batch_laws` (one arm is a batch of one). Cartesian quantities live in
the arm base frame; twists and wrenches are (linear, angular) with torques about the TCP.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS

Vec = NDArray[np.float64]


def _as_array(field: str) -> cached_property[Vec]:
    """The tuple gain `field` as a float array, made once per instance (read every period)."""
    return cached_property(lambda self: np.asarray(getattr(self, field), dtype=float))


def _positive(name: str, values: tuple[float, ...], n: int, strict: bool = False) -> None:
    if len(values) != n:
        raise ConfigError(f"{name} needs {n} values, got {len(values)}")
    if not all((v > 0) if strict else (v >= 0) for v in values):
        raise ConfigError(f"{name}={values} must be {'>' if strict else '>='} 0")


@dataclass(frozen=True)
class JointGains:
    """Joint PD for transit (franka_ros' joint impedance example gains)."""

    kp: tuple[float, ...] = (600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0)
    kd: tuple[float, ...] = (50.0, 50.0, 50.0, 20.0, 20.0, 20.0, 10.0)

    def __post_init__(self) -> None:
        _positive("kp", self.kp, N_JOINTS, strict=True)
        _positive("kd", self.kd, N_JOINTS)

    kp_array = _as_array("kp")
    kd_array = _as_array("kd")


@dataclass(frozen=True)
class ImpedanceGains:
    """K_d and D_d of seed Eq. 1 (M_d is the arm's own Cartesian inertia: no inertia shaping,
    which would need F_s that Eq. 3 deliberately leaves out)."""

    stiffness: tuple[float, ...] = (3000.0, 3000.0, 3000.0, 300.0, 300.0, 300.0)
    """[N/m] x3, [N m/rad] x3."""
    damping: tuple[float, ...] = (150.0, 150.0, 150.0, 12.0, 12.0, 12.0)
    """[N s/m] x3, [N m s/rad] x3; about critical for the arm's ~2 kg / 0.05 kg m^2 at the TCP."""
    nullspace_stiffness: float = 20.0
    """Pull of the redundant (elbow) motion toward the posture target [N m/rad]."""
    nullspace_damping: float = 4.0

    def __post_init__(self) -> None:
        _positive("stiffness", self.stiffness, 6, strict=True)
        _positive("damping", self.damping, 6)
        _positive("nullspace gains", (self.nullspace_stiffness, self.nullspace_damping), 2)

    stiffness_array = _as_array("stiffness")
    damping_array = _as_array("damping")


@dataclass(frozen=True)
class ForcePositionGains:
    """Direct force-position control (seed Fig. 4): the impedance loop tracks a reference that
    the force error moves along the force axis, plus the force fed forward and back directly."""

    impedance: ImpedanceGains = field(default_factory=ImpedanceGains)
    admittance: float = 2e-3
    """Reference speed per newton of force error [m/(N s)]: 10 mm/s toward contact at 5 N."""
    force_feedback: float = 0.5
    """Proportional gain of the measured force error added to the commanded force [-]."""
    max_offset_rate: float = 0.02
    """Clamp of the reference speed along the force axis [m/s]."""
    max_offset: float = 0.02
    """Clamp of the reference offset [m]: bounds the push if contact is never made."""
    max_speed: float = 0.003
    """Speed limit along the force axis [m/s] beyond the reference's own speed, like an
    industrial force mode's: above it the push
    is cut by speed_damping per m/s. Without it a journal that slips off the chamfer into its
    bore is driven by the full F_d + k_f F_d (7.5 N, nothing resisting) and strikes the seat at
    ~24 mm/s: 26-36 N peaks on tight holes."""
    speed_damping: float = 3000.0
    """[N s/m]: 2.4 mm/s over the limit absorbs the 7.5 N push. The arm's Cartesian inertia
    along the insertion axis is ~6 kg, so one 1 ms period removes at most half the excess speed
    (stable without a velocity filter); encoder velocity noise (~0.5 mm/s at the TCP) adds
    ~1.5 N only while over the limit."""

    def __post_init__(self) -> None:
        _positive("admittance etc.", (self.admittance, self.force_feedback), 2)
        _positive("offset clamps", (self.max_offset_rate, self.max_offset), 2, strict=True)
        _positive("speed limit", (self.max_speed, self.speed_damping), 2, strict=True)


@dataclass(frozen=True, eq=False)
class CartesianTarget:
    """Desired TCP pose, twist and acceleration (arm base frame)."""

    pos: Vec
    rot: Vec
    vel: Vec = field(default_factory=lambda: np.zeros(6))
    acc: Vec = field(default_factory=lambda: np.zeros(6))


@dataclass(frozen=True, eq=False)
class ForceTarget:
    """Push with `force` newtons along the unit vector `axis` (the insertion direction)."""

    axis: Vec
    force: float

    def __post_init__(self) -> None:
        n = float(np.linalg.norm(self.axis))
        if not abs(n - 1.0) < 1e-9:
            raise ConfigError(f"force axis must be a unit vector, got norm {n:.6g}")


def orientation_error(rot: Vec, target_rot: Vec, out: Vec | None = None) -> Vec:
    """Rotation vector taking rot to target_rot, in the base frame [rad] (into `out` if given):
    mju_mat2Quat, mju_negQuat, mju_mulQuat, mju_quat2Vel (the reference batch_laws' row-wise
    copy is tested against, and what it runs for a few rows)."""
    quat_err, q1, q2 = np.empty(4), np.empty(4), np.empty(4)  # each written whole
    mujoco.mju_mat2Quat(q1, np.ascontiguousarray(rot).ravel())
    mujoco.mju_mat2Quat(q2, np.ascontiguousarray(target_rot).ravel())
    mujoco.mju_negQuat(q1, q1)
    mujoco.mju_mulQuat(quat_err, q2, q1)
    out = np.empty(3) if out is None else out
    mujoco.mju_quat2Vel(out, quat_err, 1.0)
    return out
