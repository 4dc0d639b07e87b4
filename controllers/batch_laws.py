"""The arm control laws: pure functions of (nominal model terms at the measured state, targets,
gains) over a leading batch axis N; one arm is a batch of one.

Every law returns joint torques including the model's gravity and Coriolis terms; the caller
saturates them. Matrix products run per trial through np.matmul, which takes the BLAS kernels a
single ``@`` takes, and the quaternion helpers spell out MuJoCo's mju_ functions, so a trial's
torque does not depend on the batch it runs in (bit for bit: tests/test_batch_controller.py) and
is what the single-arm laws gave, to the last bits a CPU's vector paths change
(tests/test_arm_controller_reference.py). Trials may run
different laws: ``law_torque`` evaluates each law on the trials that are in it. The gains and
target types are :mod:`serpar.controllers.arm_laws`'.
"""

from __future__ import annotations

from typing import NamedTuple

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.controllers import arm_laws
from serpar.controllers.arm_config import ArmControllerConfig, ControlLaw
from serpar.controllers.arm_laws import (
    CartesianTarget,
    ForcePositionGains,
    ForceTarget,
    ImpedanceGains,
    JointGains,
)
from serpar.controllers.batch_linalg import dot, inverse_each, mat_vec
from serpar.controllers.batch_model import ArmTerms, Ids
from serpar.errors import ConfigError

Arr = NDArray[np.float64]

LAWS: tuple[ControlLaw, ...] = tuple(ControlLaw)
"""A trial's law is stored as its index here (an int8 array over the batch)."""
LAW_CODE: dict[ControlLaw, int] = {law: k for k, law in enumerate(LAWS)}


# NamedTuples, not frozen dataclasses: one is built every period (a third of the cost)
class BatchCartesianTarget(NamedTuple):
    """Desired TCP pose, twist and acceleration of N trials (arm base frame)."""

    pos: Arr
    """(N, 3) [m]."""
    rot: Arr
    """(N, 3, 3)."""
    vel: Arr
    """(N, 6) (linear, angular)."""
    acc: Arr
    """(N, 6)."""

    @classmethod
    def stack(cls, targets: list[CartesianTarget]) -> BatchCartesianTarget:
        return cls(*(np.stack([np.asarray(getattr(t, f), dtype=float) for t in targets])
                     for f in ("pos", "rot", "vel", "acc")))

    def take(self, ids: Ids) -> BatchCartesianTarget:
        return BatchCartesianTarget(self.pos[ids], self.rot[ids], self.vel[ids], self.acc[ids])


class BatchForceTarget(NamedTuple):
    """Push with `force` newtons along the unit `axis`, per trial."""

    axis: Arr
    """(N, 3) unit vectors."""
    force: Arr
    """(N,) [N]."""

    @classmethod
    def checked(cls, axis: Arr, force: Arr) -> BatchForceTarget:
        """Validated targets (once when set, not per period): unit axes as ForceTarget."""
        norm = np.sqrt(dot(axis, axis))
        if not np.all(np.abs(norm - 1.0) < 1e-9):
            raise ConfigError(f"force axes must be unit vectors, got norms {norm}")
        return cls(axis, force)

    @classmethod
    def stack(cls, targets: list[ForceTarget]) -> BatchForceTarget:
        return cls(np.stack([np.asarray(t.axis, dtype=float) for t in targets]),
                   np.array([float(t.force) for t in targets]))

    def take(self, ids: Ids) -> BatchForceTarget:
        return BatchForceTarget(self.axis[ids], self.force[ids])


class BatchTargets(NamedTuple):
    """Each trial's law and targets; a law reads only the rows of its own trials."""

    law: NDArray[np.int8]
    """(N,) index into LAWS."""
    q: Arr
    """(N, 7) joint target of JOINT_PD [rad]."""
    dq: Arr
    """(N, 7) joint velocity target of JOINT_PD [rad/s]."""
    cart: BatchCartesianTarget
    force: BatchForceTarget
    has_force: NDArray[np.bool_]
    """(N,) whether a ForceTarget is set (under IMPEDANCE its force is fed forward)."""
    offset: Arr
    """(N,) force-position reference offset along the axis [m]."""
    posture: Arr
    """(N, 7) nullspace posture target [rad]."""


def atan2(y: Arr, x: Arr) -> Arr:
    """The C library's atan2, row-wise. np.arctan2 is SIMD code on AVX-512 machines and
    differs from the libm atan2 that mju_quat2Vel calls by one ulp in ~2 % of cases; the
    argument of a complex log is libm's carg, i.e. its atan2 (checked in the tests)."""
    z = np.empty(np.shape(y), dtype=complex)
    z.real, z.imag = x, y
    with np.errstate(divide="ignore"):  # log|0| = -inf: only the argument is used
        return np.log(z).imag


# --- MuJoCo's quaternion functions, row-wise (engine_util_spatial.c / engine_util_blas.c) -------
# mju_mat2Quat's four branches (which component is largest) as tables, so every row is one
# gather: the signs of m0, m4, m8 under the square root, then per component (i, j, sign) of
# 0.25 (m_i +- m_j) / lead (the lead's own slot is a dummy, overwritten). a + (-b) is a - b
# exactly, so the signs cost no rounding.
_SQRT_SIGN = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)
_I = np.array([[0, 7, 2, 3], [7, 0, 1, 2], [2, 1, 0, 5], [3, 2, 5, 0]])
_J = np.array([[0, 5, 6, 1], [5, 0, 3, 6], [6, 3, 0, 7], [1, 6, 7, 0]])
_SIGN = np.array([[1, -1, -1, -1], [-1, 1, 1, 1], [-1, 1, 1, 1], [-1, 1, 1, 1]], dtype=float)
_DIAG = np.array([0, 4, 8])
_NEG = np.array([1.0, -1.0, -1.0, -1.0])
_MINVAL = mujoco.mjMINVAL


def mat2quat(rot: Arr) -> Arr:
    """mju_mat2Quat of (N, 3, 3) rotation matrices: (N, 4) (w, x, y, z)."""
    m = np.ascontiguousarray(rot).reshape(-1, 9)
    diag = m[:, _DIAG]
    m0, m4, m8 = diag.T
    branch = np.where(m0 + m4 + m8 > 0, 0,
                      np.where((m0 > m4) & (m0 > m8), 1, np.where(m4 > m8, 2, 3)))
    t = _SQRT_SIGN[branch] * diag
    lead = 0.5 * np.sqrt(((1 + t[:, 0]) + t[:, 1]) + t[:, 2])
    rows = np.arange(len(m))[:, None]
    q = 0.25 * (m[rows, _I[branch]] + _SIGN[branch] * m[rows, _J[branch]]) / lead[:, None]
    q[rows[:, 0], branch] = lead
    # mju_normalize4; MuJoCo 4 sums the squares in pairs
    sq = q * q
    norm = np.sqrt((sq[:, 0] + sq[:, 1]) + (sq[:, 2] + sq[:, 3]))
    q *= np.where(np.abs(norm - 1) > _MINVAL, 1 / norm, 1.0)[:, None]
    return np.where((norm < _MINVAL)[:, None], (1.0, 0.0, 0.0, 0.0), q)


# mju_mulQuat: component k is (p0 + p1) + (p2 + p3) of the signed products qa_j qb_{_MUL[k, j]}
_MUL = np.array([[0, 1, 2, 3], [1, 0, 3, 2], [2, 3, 0, 1], [3, 2, 1, 0]])
_MUL_SIGN = np.array([[1, -1, -1, -1], [1, 1, 1, -1], [1, -1, 1, 1], [1, 1, -1, 1]], dtype=float)


def mul_quat(qa: Arr, qb: Arr) -> Arr:
    """mju_mulQuat row-wise; MuJoCo 4 adds each component's four products in pairs."""
    p = _MUL_SIGN * (qa[:, None, :] * qb[:, _MUL])  # (-a) b is -(a b) exactly
    return (p[..., 0] + p[..., 1]) + (p[..., 2] + p[..., 3])


def quat2vel(quat: Arr) -> Arr:
    """mju_quat2Vel(res, quat, dt=1) row-wise: the rotation vector [rad]."""
    x, y, z = quat[:, 1], quat[:, 2], quat[:, 3]
    sin_half = np.sqrt(x * x + y * y + z * z)  # mju_normalize3
    big = (sin_half >= _MINVAL)[:, None]
    axis = np.where(big, quat[:, 1:] * np.where(big[:, 0], 1 / sin_half, 1.0)[:, None],
                    (1.0, 0.0, 0.0))
    speed = 2 * atan2(sin_half, quat[:, 0])
    speed = np.where(speed > np.pi, speed - 2 * np.pi, speed)
    return axis * speed[:, None]


ROWWISE_MAX = 8
"""Up to this many rows :func:`orientation_error` calls MuJoCo's own functions row by row (five
calls a row); above it the ~80 numpy calls of the vectorised copy cost less. Same numbers."""


def orientation_error(rot: Arr, target_rot: Arr, out: Arr | None = None) -> Arr:
    """(N, 3) rotation vectors taking rot to target_rot, in the base frame [rad] (into `out`
    if given)."""
    if len(rot) > ROWWISE_MAX:
        err = orientation_error_vectorised(rot, target_rot)
        if out is None:
            return err
        out[:] = err
        return out
    out = np.empty((len(rot), 3)) if out is None else out
    for a, b, row in zip(rot, target_rot, out):
        arm_laws.orientation_error(a, b, row)
    return out


def orientation_error_vectorised(rot: Arr, target_rot: Arr) -> Arr:
    """:func:`orientation_error` as numpy calls over the whole batch: mju_mat2Quat, mju_negQuat,
    mju_mulQuat and mju_quat2Vel row-wise."""
    n = len(rot)
    with np.errstate(divide="ignore", invalid="ignore"):  # the masked-out rows' 1/0
        quats = mat2quat(np.concatenate([rot, target_rot]))
        return quat2vel(mul_quat(quats[n:], quats[:n] * _NEG))  # target * neg(rot)


# --- the laws ----------------------------------------------------------------------------------
def pose_error(terms: ArmTerms, target: BatchCartesianTarget) -> Arr:
    """(N, 6) position and orientation error of the TCP to the target."""
    err = np.empty((len(terms.pos), 6))
    np.subtract(target.pos, terms.pos, out=err[:, :3])
    orientation_error(terms.rot, target.rot, err[:, 3:])
    return err


def joint_pd_torque(terms: ArmTerms, q_target: Arr, dq_target: Arr, gains: JointGains) -> Arr:
    """tau = Kp (q* - q) + Kd (dq* - dq) + c + g."""
    return gains.kp_array * (q_target - terms.q) + gains.kd_array * (dq_target - terms.dq) + terms.bias


def impedance_torque(terms: ArmTerms, target: BatchCartesianTarget, gains: ImpedanceGains,
                     force_ff: Arr | None, q_posture: Arr) -> Arr:
    """Seed Eq. 3: tau = J^T (F_d + Lambda acc* + K_d dx + D_d dv) + c + g + nullspace posture;
    `force_ff` is F_d (N, 6) or None."""
    jac, dq, jdot_dq = terms.jac, terms.dq, terms.jdot_dq
    if jdot_dq is None:
        raise ConfigError("the Cartesian laws need terms loaded with Jdot dq (terms(jdot=True))")
    jac_t = jac.transpose(0, 2, 1)
    minv_jt = np.linalg.solve(terms.mass, jac_t)
    lam = inverse_each(np.matmul(jac, minv_jt))
    # acc* - Jdot dq: the Cartesian acceleration the joint accelerations must add
    acc = target.acc - jdot_dq
    wrench = (mat_vec(lam, acc) + gains.stiffness_array * pose_error(terms, target)
              + gains.damping_array * (target.vel - mat_vec(jac, dq)))
    if force_ff is not None:
        wrench = wrench + force_ff
    tau_null = gains.nullspace_stiffness * (q_posture - terms.q) - gains.nullspace_damping * dq
    # Dynamically consistent projection (I - J^T Lambda J M^-1) tau_null, as vectors: the
    # posture torque cannot disturb the TCP.
    wrench = wrench - mat_vec(lam, mat_vec(minv_jt.transpose(0, 2, 1), tau_null))
    return mat_vec(jac_t, wrench) + tau_null + terms.bias


def force_position_torque(terms: ArmTerms, target: BatchCartesianTarget,
                          gains: ForcePositionGains, force: BatchForceTarget,
                          measured_force: Arr, offset: Arr, q_posture: Arr) -> Arr:
    """Fig. 4: impedance about target shifted by `offset` along the axis, plus
    (F_d + k_f (F_d - F_s)) along the axis, less the speed limit's brake; measured_force is F_s
    (N,) along the axis."""
    axis = force.axis
    shifted = BatchCartesianTarget(target.pos + offset[:, None] * axis, target.rot, target.vel,
                                   target.acc)
    push = force.force + gains.force_feedback * (force.force - measured_force)
    # The limit is on speed beyond the reference's own (a commanded move along the axis is not
    # braked; a push into a hole from a held pose is).
    velocity = mat_vec(terms.jac[:, :3], terms.dq)
    excess = dot(axis, velocity - target.vel[:, :3]) - gains.max_speed
    push = push - gains.speed_damping * np.maximum(0.0, excess)
    ff = np.concatenate([push[:, None] * axis, np.zeros((len(push), 3))], axis=1)
    return impedance_torque(terms, shifted, gains.impedance, ff, q_posture)


def next_force_offset(offset: Arr, force: BatchForceTarget, measured_force: Arr,
                      gains: ForcePositionGains, dt: float) -> Arr:
    """Integrate the reference offsets: d(offset)/dt = admittance (F_d - F_s), clamped; toward
    the push no faster than the speed limit, else the reference winds up ahead of a braked TCP
    and the stored spring force overshoots the target on contact. (np.minimum of np.maximum:
    np.clip's arithmetic without its Python wrapper, which costs more than the clip at N = 1.)"""
    rate = np.minimum(np.maximum(gains.admittance * (force.force - measured_force),
                                 -gains.max_offset_rate),
                      min(gains.max_offset_rate, gains.max_speed))
    return np.minimum(np.maximum(offset + rate * dt, -gains.max_offset), gains.max_offset)


def laws_present(law: NDArray[np.int8]) -> tuple[int, ...]:
    """The codes of the laws some trial is in (ascending)."""
    return tuple(int(k) for k in np.flatnonzero(np.bincount(law, minlength=len(LAWS))))


def law_torque(terms: ArmTerms, targets: BatchTargets, measured_push: Arr | None,
               config: ArmControllerConfig, present: tuple[int, ...] | None = None) -> Arr:
    """(N, 7) torques, each trial by its own law (unsaturated; includes c + g); measured_push
    is F_s (N,), read only by FORCE_POSITION trials (None when there are none); `present`:
    :func:`laws_present` of targets.law, if the caller keeps it."""
    present = laws_present(targets.law) if present is None else present
    if len(present) == 1:  # every trial in one law: views, no gathers
        return _one_law(LAWS[present[0]], terms, targets, slice(None), measured_push, config)
    tau = np.empty((len(targets.law), terms.q.shape[1]))
    for code in present:
        ids = np.flatnonzero(targets.law == code)
        tau[ids] = _one_law(LAWS[code], terms.take(ids), targets, ids, measured_push, config)
    return tau


def _one_law(law: ControlLaw, terms: ArmTerms, targets: BatchTargets, ids: Ids | slice,
             measured_push: Arr | None, config: ArmControllerConfig) -> Arr:
    """The torques of trials `ids`, all in `law` (`terms` already theirs)."""
    whole = isinstance(ids, slice)
    if law is ControlLaw.JOINT_PD:
        return joint_pd_torque(terms, targets.q[ids], targets.dq[ids], config.joint)
    cart = targets.cart if whole else targets.cart.take(ids)
    force = targets.force if whole else targets.force.take(ids)
    posture = targets.posture[ids]
    if law is ControlLaw.IMPEDANCE:
        # Eq. 3's F_d is fed forward where a ForceTarget is set (x + 0.0 == x elsewhere)
        has = targets.has_force[ids]
        ff = None
        if has.any():
            ff = np.concatenate([force.force[:, None] * force.axis, np.zeros((len(has), 3))],
                                axis=1)
            ff[~has] = 0.0
        return impedance_torque(terms, cart, config.impedance, ff, posture)
    if measured_push is None:
        raise ConfigError("force_position trials need the measured push F_s")
    return force_position_torque(terms, cart, config.force_position, force, measured_push[ids],
                                 targets.offset[ids], posture)
