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

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.sim.arm import JOINT_NAMES, Q_MAX, Q_MIN, build_arm_spec

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


@dataclass(frozen=True, eq=False)
class ArmModel:
    """One arm as the dynamics diagnosis and its twins see it, whatever its joint count: how to
    build its MuJoCo spec (the nominal model: masses, inertias, armature, damping as its file
    gives them), the chain of hinge joints from the base to the flange, the link each joint
    moves, and the flange. The Panda is :data:`PANDA_ARM`; an arm from a URDF/MJCF file is
    built by ``serpar.sim.robot_dynamics.arm_from_file``. Every effect reads the arm from here,
    so there is one code path for every arm."""

    name: str
    source: str
    """``built-in`` or the model file's path."""
    make_spec: Callable[[], mujoco.MjSpec]
    joint_names: tuple[str, ...]
    """The chain's joints, base to flange (joint j of the recording is the j-th)."""
    link_bodies: tuple[str, ...]
    """The body each joint moves (its child link), whose inertia ``link_inertia`` scales."""
    flange_body: str
    flange_pos: tuple[float, float, float]
    """The flange origin in the flange body's frame [m] (a payload's CoM is counted from it)."""
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    notes: tuple[str, ...] = ()
    """What reading the file repaired, one line each (body and value named)."""
    inertials_identified: bool = False
    """The file's link masses, centres of mass and inertias were identified on this arm (the
    Panda's: Gaz et al. 2019), not taken from CAD: a diagnosis then looks for their scale
    errors only (``link_inertia``), not for every base inertial parameter (``link_inertial``),
    whose dozens of parameters a CAD model needs."""
    friction_bounds: tuple[float, float] = (10.0, 5.0)
    """Largest joint friction searched: Coulomb [N m], viscous [N m s/rad]. The Panda's
    drives: 10 and 5; an arm from a file: from its joints' torque limits
    (``serpar.sim.robot_dynamics``)."""

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        if n < 1 or len(self.link_bodies) != n or len(self.q_min) != n or len(self.q_max) != n:
            raise IdentificationError(f"arm {self.name}: {n} joints need as many link bodies and "
                                      "joint limits")

    @property
    def n(self) -> int:
        return len(self.joint_names)

    @property
    def is_panda(self) -> bool:
        return self.source == "built-in"


PANDA_ARM = ArmModel("the Panda", "built-in", rigid_arm_spec, JOINT_NAMES, LINK_BODIES, FLANGE_BODY,
                     (0.0, 0.0, FLANGE_Z), tuple(map(float, Q_MIN)), tuple(map(float, Q_MAX)),
                     inertials_identified=True)
"""serpar's own arm, the default of every arm-dynamics command."""


@dataclass(frozen=True)
class DynamicsSeries:
    """Inverse dynamics of one model over samples (rows x 7 joints)."""

    link: Vec
    full: Vec


class ArmDynamics:
    """Inverse dynamics of a compiled rigid arm, evaluated sample by sample with ``mj_rne``.

    The model is the caller's and may be edited in place between calls (body masses,
    inertias, CoMs): ``mj_rne`` reads them afresh at every sample. Only the arm's chain
    (``arm.joint_names``) moves; any other joint of the model (none for the Panda's rigid arm)
    stays at its reference.
    """

    def __init__(self, model: mujoco.MjModel | None = None, arm: ArmModel = PANDA_ARM) -> None:
        self.arm = arm
        self.model = model if model is not None else arm.make_spec().compile()
        try:
            joints = [self.model.joint(n) for n in arm.joint_names]
        except KeyError as exc:
            raise IdentificationError(f"the model of {arm.name} lacks joint {exc}") from None
        self.n = len(joints)
        self.dof = np.array([j.dofadr[0] for j in joints], np.int64)
        self.qpos = np.array([j.qposadr[0] for j in joints], np.int64)
        self._simple = (self.model.nv == self.n and np.array_equal(self.dof, np.arange(self.n))
                        and np.array_equal(self.qpos, np.arange(self.n)))
        self.data = mujoco.MjData(self.model)
        self._out = np.zeros(self.model.nv)
        self._mass = np.zeros((self.model.nv, self.model.nv))

    @property
    def armature(self) -> Vec:
        return self.model.dof_armature[self.dof].copy()

    @property
    def damping(self) -> Vec:
        return self.model.dof_damping[self.dof].copy()

    def link_torque(self, q: Vec, dq: Vec, ddq: Vec) -> Vec:
        """rows x n: M_link(q) ddq + c(q, dq) + g(q) per row."""
        m, d, out = self.model, self.data, np.empty_like(q)
        simple, qpos, dof = self._simple, self.qpos, self.dof
        for k in range(len(q)):
            if simple:
                d.qpos[:] = q[k]
                d.qvel[:] = dq[k]
                d.qacc[:] = ddq[k]
            else:
                d.qpos[qpos] = q[k]
                d.qvel[dof] = dq[k]
                d.qacc[dof] = ddq[k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_comVel(m, d)
            mujoco.mj_rne(m, d, 1, self._out)
            out[k] = self._out if simple else self._out[dof]
        return out

    def series(self, q: Vec, dq: Vec, ddq: Vec) -> DynamicsSeries:
        link = self.link_torque(q, dq, ddq)
        return DynamicsSeries(link, link + self.armature * ddq + self.damping * dq)

    def mass_link_and_full(self, q: Vec) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """rows x n x n: the link-side inertia (no armature) and the drive-side one."""
        m, d, dof = self.model, self.data, self.dof
        link = np.empty((len(q), self.n, self.n))
        for k in range(len(q)):
            d.qpos[self.qpos] = q[k]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_crb(m, d)
            mujoco.mj_fullM(m, d, self._mass)
            link[k] = self._mass[np.ix_(dof, dof)]
        full = link.copy()
        link -= np.diag(self.armature)  # mj_crb adds armature to the diagonal
        return link, full

    def gravity(self, q: Vec) -> Vec:
        """rows x n: g(q), the torque that holds the arm still."""
        zeros = np.zeros_like(q)
        return self.link_torque(q, zeros, zeros)
