"""Backlash in MuJoCo's own terms: every joint of the arm is a limited hinge whose range is
the gearbox clearance about the motor angle (zero width for a joint without backlash), with
the gearbox's dry friction as ``frictionloss``. A pose is reached the way a real arm gets
there: the motors run a slow minimum-jerk move of a few milliradians in the approach
direction into the commanded angles, so the moving clearance drags every link whose gravity
load the friction holds to the trailing side, a link that gravity loads beyond the friction
in the approach direction runs ahead to the leading side, and MuJoCo integrates gravity, the
gearbox friction and the stiff limit constraints until the arm is at rest.

Releasing every link at once from the trailing side with the motors still would let the
links that gravity carries across their clearance strike the far end together, and the jolt
moves a few sub-threshold links off their side, which no static model can follow (held-out
RMS 1.8-2.4x the noise on seeds 0-3, against 1.01-1.72x with the dragging approach;
``tests/test_diagnosis_arm_static.py``).
"""

from __future__ import annotations

import copy

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm import JOINT_NAMES
from serpar.sim.physics import PhysicsConfig

TIMESTEP_S = 5 * PhysicsConfig().timestep
"""A static settle resolves no contact, so it steps 5x the cell's step: the limits' stiffest
solref (2 steps) stays well under the approach move's time scale, at a fifth of the steps."""
SETTLE_S = 0.4
"""[s] at rest after the approach."""
APPROACH_S = 1.0
"""[s] of the motors' minimum-jerk approach move; its accelerations (~0.01 rad/s^2) put
inertial torques two orders below the gearbox friction on every link."""
APPROACH_EXTRA_RAD = 1e-3
"""The approach move is the clearance's full width plus this, so it catches a link anywhere
in its clearance and drags it at least this far."""
PIN_RAD = 1e-9
"""Half-width of the range of a joint without backlash (a two-sided stiff limit pins it)."""
LIMIT_SOLREF = (2 * TIMESTEP_S, 1.0)
LIMIT_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)
DAMPING = 5.0
"""[N m s/rad]: the gearbox's viscous loss, so a released link comes to rest quickly."""
REST_RAD_S = 1e-4
"""[rad/s]: "at rest". MuJoCo's dry friction is a soft constraint: a link that gravity loads
below the friction still creeps, so a
few links per hundred poses end part-way across their clearance. The twin reports how many
poses were still moving (answer ``creeping_poses``) rather than hiding them; the no-slip
solver and a stiffer friction impedance were tried and made it worse."""


def settle_with_backlash(model: mujoco.MjModel, q_cmd: NDArray[np.float64],
                         approach: NDArray[np.float64], half: NDArray[np.float64],
                         friction_nm: float
                         ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Link angles (N, 7) at rest after the approach for motor angles ``q_cmd`` (N, 7) reached from
    direction ``approach`` (+1 / -1 per joint), clearance half-widths ``half`` [rad] per
    joint; and per pose whether a link was still creeping (faster than REST_RAD_S)."""
    m = copy.copy(model)  # the caller's model keeps its own limits and friction
    dof = np.array([m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)]
                    for j in JOINT_NAMES])
    jnt = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in JOINT_NAMES])
    if m.nv != len(JOINT_NAMES):
        raise ConfigError(f"the backlash plant expects {len(JOINT_NAMES)} hinges, the model has "
                          f"{m.nv} degrees of freedom")
    m.opt.timestep = TIMESTEP_S
    m.jnt_limited[jnt] = 1
    m.jnt_solref[jnt] = LIMIT_SOLREF
    m.jnt_solimp[jnt] = LIMIT_SOLIMP
    m.dof_damping[dof] = DAMPING
    m.dof_frictionloss[dof] = np.where(np.asarray(half) > 0, friction_nm, 0.0)
    m.dof_solref[dof] = LIMIT_SOLREF  # the stiffest friction the timestep allows: least creep
    width = np.maximum(np.asarray(half, float), PIN_RAD)
    d = mujoco.MjData(m)
    out = np.empty_like(np.atleast_2d(q_cmd))
    moving = np.zeros(len(out), bool)
    s = np.linspace(0.0, 1.0, round(APPROACH_S / TIMESTEP_S) + 1)[1:]
    shape = np.r_[10 * s**3 - 15 * s**4 + 6 * s**5, np.ones(round(SETTLE_S / TIMESTEP_S))]
    travel = 2 * np.asarray(half, float) + APPROACH_EXTRA_RAD
    for n, (qc, a) in enumerate(zip(np.atleast_2d(q_cmd), np.atleast_2d(approach))):
        start = qc - a * travel
        mujoco.mj_resetData(m, d)
        d.qpos[dof] = start - a * np.asarray(half)  # trailing the motor it follows
        for f in shape:
            motor = start + (qc - start) * f
            m.jnt_range[jnt, 0] = motor - width
            m.jnt_range[jnt, 1] = motor + width
            mujoco.mj_step(m, d)
        moving[n] = np.abs(d.qvel).max() > REST_RAD_S
        out[n] = d.qpos[dof]
    return out, moving
