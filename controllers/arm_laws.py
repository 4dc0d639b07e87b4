"""Arm control laws as pure functions of (nominal model at the measured state, target, gains).

Every law returns joint torques including the model's gravity and Coriolis terms; the
caller saturates them. Cartesian quantities live in the arm base frame; twists and
wrenches are (linear, angular) with torques about the TCP.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_model import NominalArm
from serpar.errors import ConfigError
from serpar.sim.arm import HOME_Q, N_JOINTS

Vec = NDArray[np.float64]


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

    @cached_property
    def stiffness_array(self) -> Vec:
        return np.asarray(self.stiffness, dtype=float)

    @cached_property
    def damping_array(self) -> Vec:
        return np.asarray(self.damping, dtype=float)


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


def orientation_error(rot: Vec, target_rot: Vec) -> Vec:
    """Rotation vector taking rot to target_rot, in the base frame [rad]."""
    quat_err, q1, q2 = np.zeros(4), np.zeros(4), np.zeros(4)
    mujoco.mju_mat2Quat(q1, np.ascontiguousarray(rot).ravel())
    mujoco.mju_mat2Quat(q2, np.ascontiguousarray(target_rot).ravel())
    mujoco.mju_negQuat(q1, q1)
    mujoco.mju_mulQuat(quat_err, q2, q1)
    out = np.zeros(3)
    mujoco.mju_quat2Vel(out, quat_err, 1.0)
    return out


def pose_error(nominal: NominalArm, target: CartesianTarget) -> Vec:
    pos, rot = nominal.tcp_pose()
    return np.concatenate([target.pos - pos, orientation_error(rot, target.rot)])


def joint_pd_torque(nominal: NominalArm, q_target: Vec, dq_target: Vec, gains: JointGains) -> Vec:
    """tau = Kp (q* - q) + Kd (dq* - dq) + c + g."""
    q, dq = nominal.data.qpos[nominal.index.qpos], nominal.data.qvel[nominal.index.dof]
    return np.asarray(gains.kp) * (q_target - q) + np.asarray(gains.kd) * (dq_target - dq) + nominal.bias()


def impedance_torque(nominal: NominalArm, target: CartesianTarget, gains: ImpedanceGains,
                     force_ff: Vec | None = None, q_posture: Vec | None = None) -> Vec:
    """Seed Eq. 3: tau = J^T (F_d + Lambda acc* + K_d dx + D_d dv) + c + g + nullspace posture."""
    idx = nominal.index
    q, dq = nominal.data.qpos[idx.qpos], nominal.data.qvel[idx.dof]
    jac = nominal.tcp_jacobian()
    minv_jt = np.linalg.solve(nominal.mass(), jac.T)
    lam = np.linalg.inv(jac @ minv_jt)
    # acc* - Jdot dq: the Cartesian acceleration the joint accelerations must add.
    acc = target.acc - nominal.tcp_jacobian_dot() @ dq
    wrench = (lam @ acc + gains.stiffness_array * pose_error(nominal, target)
              + gains.damping_array * (target.vel - jac @ dq))
    if force_ff is not None:
        wrench = wrench + force_ff
    posture = HOME_Q if q_posture is None else q_posture
    tau_null = gains.nullspace_stiffness * (posture - q) - gains.nullspace_damping * dq
    # Dynamically consistent projection (I - J^T Lambda J M^-1) tau_null, as vectors: the
    # posture torque cannot disturb the TCP.
    wrench = wrench - lam @ (minv_jt.T @ tau_null)
    return jac.T @ wrench + tau_null + nominal.bias()


def force_position_torque(nominal: NominalArm, target: CartesianTarget, gains: ForcePositionGains,
                          force: ForceTarget, measured_force: float, offset: float,
                          q_posture: Vec | None = None) -> Vec:
    """Fig. 4: impedance about target shifted by `offset` along the axis, plus
    (F_d + k_f (F_d - F_s)) along the axis, less the speed limit's brake; measured_force is F_s
    along the axis."""
    shifted = CartesianTarget(target.pos + offset * force.axis, target.rot, target.vel, target.acc)
    push = force.force + gains.force_feedback * (force.force - measured_force)
    # The limit is on speed beyond the reference's own (a commanded move along the axis is not
    # braked; a push into a hole from a held pose is).
    velocity = nominal.tcp_jacobian()[:3] @ nominal.data.qvel[nominal.index.dof]
    excess = float(force.axis @ (velocity - target.vel[:3])) - gains.max_speed
    push -= gains.speed_damping * max(0.0, excess)
    ff = np.concatenate([push * force.axis, np.zeros(3)])
    return impedance_torque(nominal, shifted, gains.impedance, ff, q_posture)


def next_force_offset(offset: float, force: ForceTarget, measured_force: float,
                      gains: ForcePositionGains, dt: float) -> float:
    """Integrate the reference offset: d(offset)/dt = admittance (F_d - F_s), clamped; toward
    the push no faster than the speed limit, else the reference winds up ahead of a braked TCP
    and the stored spring force overshoots the target on contact."""
    rate = np.clip(gains.admittance * (force.force - measured_force), -gains.max_offset_rate,
                   min(gains.max_offset_rate, gains.max_speed))
    return float(np.clip(offset + rate * dt, -gains.max_offset, gains.max_offset))
