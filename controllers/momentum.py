"""The arm's generalised momentum and the model terms its observer integrates.

Link-side dynamics (the joint torque sensors sit after the gearbox, so the rotor armature and
the motor-side viscous damping are not in it; assets/arm/README.md, "Sensors"):

    M(q) ddq + C(q, dq) dq + g(q) = tau_J + tau_ext.

The momentum p = M(q) dq changes as dp/dt = M ddq + Mdot dq, and with Mdot = C + C^T (the
Christoffel C, for which Mdot - 2C is skew) that is

    dp/dt = tau_J + tau_ext + C^T dq - g = tau_J + tau_ext - beta,
    beta = g - C^T dq = n - Mdot dq,       n = C dq + g (MuJoCo's bias force, mj_rne).

So the observer needs n, which the controller's model already has at the measured state, and
Mdot dq, the derivative of M along the motion: a central difference of mj_fullM at q -+ eps
dq/|dq| (two mass-matrix evaluations on a scratch MjData, so the controller's own data keeps
the measured state). No acceleration is ever formed.
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_model import NominalArm

Vec = NDArray[np.float64]

MDOT_STEP_RAD = 1e-5
"""Joint-space step of the central difference of M along dq [rad]: its truncation error
(~step^2 times M's third derivative) and round-off (~1e-16 / step) both stay below 1e-9."""


class MomentumTerms:
    """p = M_link(q) dq and beta = n - Mdot dq of the controller's nominal arm."""

    def __init__(self, nominal: NominalArm) -> None:
        self.nominal = nominal
        self._scratch = mujoco.MjData(nominal.model)
        self._full = np.zeros((nominal.model.nv, nominal.model.nv))
        idx = nominal.index
        self._block = np.ix_(idx.dof, idx.dof)
        # The torque sensors read after the gearbox: the reflected rotor inertia is not theirs.
        self._armature = np.diag(nominal.model.dof_armature[idx.dof])

    def link_mass(self) -> Vec:
        """7x7 link-side inertia at the nominal model's loaded q (mj_crb done by load())."""
        return self.nominal.mass() - self._armature

    def momentum(self) -> Vec:
        """p = M_link(q) dq at the loaded state [N m s]."""
        nominal = self.nominal
        return self.link_mass() @ nominal.data.qvel[nominal.index.dof]

    def mass_dot_dq(self) -> Vec:
        """Mdot dq = (d/ds M(q + s dq)) dq at s = 0, by a central difference [N m]."""
        nominal = self.nominal
        idx = nominal.index
        dq = nominal.data.qvel[idx.dof]
        speed = float(np.linalg.norm(dq))
        if speed == 0.0:
            return np.zeros(len(idx.dof))
        step = MDOT_STEP_RAD * dq / speed
        plus = self._mass_at(nominal.data.qpos[idx.qpos] + step)
        minus = self._mass_at(nominal.data.qpos[idx.qpos] - step)
        return (plus - minus) @ dq * (speed / (2 * MDOT_STEP_RAD))

    def beta(self) -> Vec:
        """beta = n - Mdot dq = g - C^T dq at the loaded state [N m]."""
        nominal = self.nominal
        return nominal.data.qfrc_bias[nominal.index.dof] - self.mass_dot_dq()

    def _mass_at(self, q: Vec) -> Vec:
        """Arm block of M at q (armature included; it cancels in the difference)."""
        m, d, idx = self.nominal.model, self._scratch, self.nominal.index
        d.qpos[:] = self.nominal.data.qpos
        d.qpos[idx.qpos] = q
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_crb(m, d)
        mujoco.mj_fullM(m, d, self._full)
        return self._full[self._block].copy()
