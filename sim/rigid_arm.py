"""The arm as the time-series diagnosis evaluates it: a rigid-hand arm model and its inverse
dynamics over many samples.

The hand's finger joints and the gripper's axial spring are removed (fingers closed, hand
rigid): the diagnosis reads free-motion recordings of the arm, in which the fingers carry no
load, so their few grams of relative motion are not part of the arm's dynamics. The same
spec is the nominal model of the diagnosis and the starting point of the effect twins
(:mod:`serpar.twins.arm_dynamics_twin`), which add their effects to it as real MuJoCo physics.

Two torques are predicted per sample (both from ``mj_rne``, never by hand-written dynamics):

* ``link``: M_link(q) q̈ + c + g, what the link-side joint torque sensors read (MuJoCo's
  ``<torque>`` sensors sit after the gearbox: no armature, no joint friction);
* ``full``: ``link`` + armature·q̈ + damping·q̇, what the drive must deliver, i.e. what the
  commanded torque should be.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.sim.arm import JOINT_NAMES, N_JOINTS, build_arm_spec

Vec = NDArray[np.float64]

HAND_ONLY_JOINTS = ("finger_left", "finger_right", "grip_compliance")
LINK_BODIES: tuple[str, ...] = tuple(f"link{i}" for i in range(1, 8))
"""The moving links whose inertia the ``link_inertia`` effect scales (the hand is tool)."""
FLANGE_BODY = "link7"
FLANGE_Z = 0.107
"""Flange origin in the link-7 frame [m] (serpar.sim.arm.FLANGE_D)."""


def rigid_arm_spec() -> mujoco.MjSpec:
    """The project's arm (``assets/arm/panda.xml``) with a rigid, closed hand."""
    spec = build_arm_spec()
    spec.delete(spec.equality("finger_coupling"))
    spec.delete(spec.actuator("grip"))
    spec.delete(spec.tendon("jaw_width"))
    for name in HAND_ONLY_JOINTS:
        spec.delete(spec.joint(name))
    return spec


@dataclass(frozen=True)
class DynamicsSeries:
    """Inverse dynamics of one model over samples (rows x 7 joints)."""

    link: Vec
    full: Vec


class ArmDynamics:
    """Inverse dynamics of a compiled rigid arm, evaluated sample by sample with ``mj_rne``.

    The model is the caller's and may be edited in place between calls (body masses,
    inertias, CoMs): ``mj_rne`` reads them afresh at every sample.
    """

    def __init__(self, model: mujoco.MjModel | None = None) -> None:
        self.model = model if model is not None else rigid_arm_spec().compile()
        if self.model.nv != N_JOINTS:
            raise IdentificationError(f"the arm model has {self.model.nv} DoF; the arm-dynamics "
                                      f"diagnosis needs the {N_JOINTS}-joint rigid arm")
        self.data = mujoco.MjData(self.model)
        self.dof = np.array([self.model.joint(n).dofadr[0] for n in JOINT_NAMES])
        if not np.array_equal(self.dof, np.arange(N_JOINTS)):
            raise IdentificationError("arm joints must be the model's first 7 DoF, in order")
        self._out = np.zeros(N_JOINTS)
        self._mass = np.zeros((N_JOINTS, N_JOINTS))

    @property
    def armature(self) -> Vec:
        return self.model.dof_armature.copy()

    @property
    def damping(self) -> Vec:
        return self.model.dof_damping.copy()

    def link_torque(self, q: Vec, dq: Vec, ddq: Vec) -> Vec:
        """rows x 7: M_link(q) ddq + c(q, dq) + g(q) per row."""
        m, d, out = self.model, self.data, np.empty_like(q)
        for k in range(len(q)):
            d.qpos[:] = q[k]
            d.qvel[:] = dq[k]
            d.qacc[:] = ddq[k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_comVel(m, d)
            mujoco.mj_rne(m, d, 1, self._out)
            out[k] = self._out
        return out

    def series(self, q: Vec, dq: Vec, ddq: Vec) -> DynamicsSeries:
        link = self.link_torque(q, dq, ddq)
        return DynamicsSeries(link, link + self.armature * ddq + self.damping * dq)

    def mass_link_and_full(self, q: Vec) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """rows x 7 x 7: the link-side inertia (no armature) and the drive-side one."""
        m, d = self.model, self.data
        link = np.empty((len(q), N_JOINTS, N_JOINTS))
        for k in range(len(q)):
            d.qpos[:] = q[k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_crb(m, d)
            mujoco.mj_fullM(m, d, self._mass)
            link[k] = self._mass
        full = link.copy()
        link -= np.diag(self.armature)  # mj_crb adds armature to the diagonal
        return link, full

    def gravity(self, q: Vec) -> Vec:
        """rows x 7: g(q), the torque that holds the arm still."""
        zeros = np.zeros_like(q)
        return self.link_torque(q, zeros, zeros)
