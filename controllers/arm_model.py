"""The arm as the controller sees it: ids in a compiled model and the nominal dynamics model.

The controller never reads the plant's MjData for its model terms: it loads the
*measured* joint state into its own arm-only model (``NominalArm``), exactly like
a real Panda controller evaluates libfranka's model from ``q`` and ``dq``. The
plant (scene) and the controller model are compiled from the same MJCF, so with
noise off the model is exact; calibration and ``diagnose`` perturb it.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError, LimitError
from serpar.sim.arm import (
    N_JOINTS,
    Q_MAX,
    Q_MIN,
    build_arm_spec,
)
from serpar.sim.arm_drive import ArmIndex

Vec = NDArray[np.float64]


class NominalArm:
    """The controller's dynamic model: an arm-only MjModel evaluated at the measured state."""

    def __init__(self, model: mujoco.MjModel | None = None) -> None:
        self.model = model if model is not None else build_arm_spec().compile()
        self.data = mujoco.MjData(self.model)
        self.index = ArmIndex.from_model(self.model)
        self._jac = np.zeros((6, self.model.nv))
        self._mass = np.zeros((self.model.nv, self.model.nv))
        self._rne = np.zeros(self.model.nv)
        self._jac_dot = np.zeros((6, self.model.nv))
        self._arm_block = np.ix_(self.index.dof, self.index.dof)

    def load(self, q: Vec, dq: Vec) -> None:
        """Evaluate kinematics, mass matrix and bias forces at (q, dq)."""
        m, d, idx = self.model, self.data, self.index
        d.qpos[idx.qpos] = q
        d.qvel[idx.dof] = dq
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)
        mujoco.mj_comVel(m, d)
        mujoco.mj_rne(m, d, 0, self._rne)
        d.qfrc_bias[:] = self._rne

    def tcp_pose(self) -> tuple[Vec, Vec]:
        """TCP position [m] and rotation matrix in the arm base frame."""
        s = self.index.tcp_site
        return self.data.site_xpos[s].copy(), self.data.site_xmat[s].reshape(3, 3).copy()

    def tcp_jacobian(self) -> Vec:
        """6x7 geometric Jacobian of the TCP (linear rows first), arm joints only."""
        mujoco.mj_jacSite(self.model, self.data, self._jac[:3], self._jac[3:], self.index.tcp_site)
        return self._jac[:, self.index.dof].copy()

    def tcp_jacobian_dot(self) -> Vec:
        """6x7 time derivative of the TCP Jacobian at the loaded (q, dq)."""
        site, jd = self.index.tcp_site, self._jac_dot
        mujoco.mj_jacDot(self.model, self.data, jd[:3], jd[3:], self.data.site_xpos[site],
                         self.model.site_bodyid[site])
        return jd[:, self.index.dof]

    def viscous_friction(self) -> Vec:
        """The model's joint viscous friction torque at dq (MJCF damping) [N m]."""
        return self.model.dof_damping[self.index.dof] * self.data.qvel[self.index.dof]

    def mass(self) -> Vec:
        """7x7 joint-space inertia including rotor armature (what the motors accelerate)."""
        mujoco.mj_fullM(self.model, self.data, self._mass)
        return self._mass[self._arm_block]

    def bias(self) -> Vec:
        """Model torques the motors must supply at rest acceleration: c(q, dq) + g(q) plus the
        model's viscous joint friction (compensated like Franka's friction observer) [N m]."""
        return self.data.qfrc_bias[self.index.dof] + self.viscous_friction()

    def link_torque(self, ddq: Vec) -> Vec:
        """M_link(q) ddq + c + g: the link-side torque the joint torque sensors should read.

        mj_rne uses body inertias only (no armature): the sensors sit after the gearbox.
        """
        self.data.qacc[:] = 0.0
        self.data.qacc[self.index.dof] = ddq
        mujoco.mj_rne(self.model, self.data, 1, self._rne)
        return self._rne[self.index.dof].copy()


def require_joint_target(q: Vec) -> Vec:
    """Raise LimitError naming the joint and its range when q is outside the Panda limits."""
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (N_JOINTS,):
        raise ConfigError(f"joint target needs {N_JOINTS} angles, got shape {q.shape}")
    for i, (v, lo, hi) in enumerate(zip(q, Q_MIN, Q_MAX)):
        if not lo <= v <= hi:
            raise LimitError(f"joint{i + 1} target {v:.4f} rad outside its limit [{lo}, {hi}] rad")
    return q
