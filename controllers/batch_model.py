"""The controller's nominal arm for N trials at once: ``NominalArm`` and ``MomentumTerms`` over a
leading batch axis, evaluated by one ``mujoco.batch.Batch`` call per period instead of N.

Every term is read from fields the batch's forward pass computes (mass matrix, bias forces,
site pose, cdof, cdof_dot, cvel, subtree_com) and combined with the arithmetic of the MuJoCo
functions the single-arm code calls (mj_fullM, mj_jacSite, mj_jacDot), in their operation order,
so a trial's terms equal ``NominalArm``'s bit for bit (tests/test_batch_controller.py).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco.batch import Batch
from numpy.typing import NDArray

from serpar.controllers.momentum import MDOT_STEP_RAD
from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS, build_arm_spec
from serpar.sim.arm_drive import ArmIndex

Arr = NDArray[np.float64]
Ids = NDArray[np.intp]


_C1, _C2 = np.array([1, 2, 0]), np.array([2, 0, 1])
_DISABLE = mujoco.mjtDisableBit
_UNUSED_STAGES = int(_DISABLE.mjDSBL_CONSTRAINT | _DISABLE.mjDSBL_SENSOR
                     | _DISABLE.mjDSBL_ACTUATION | _DISABLE.mjDSBL_SPRING | _DISABLE.mjDSBL_DAMPER)


def cross(a: Arr, b: Arr) -> Arr:
    """Row-wise a x b over (..., 3) in mju_cross's operation order (a1 b2 - a2 b1, ...)."""
    return a[..., _C1] * b[..., _C2] - a[..., _C2] * b[..., _C1]


def mat_vec(mat: Arr, vec: Arr) -> Arr:
    """(..., m, n) @ (..., n) -> (..., m): np.matmul runs the BLAS gemv per trial that the
    single-arm ``mat @ vec`` runs, bitwise the same where each trial's matrix has the single
    one's memory layout (C or Fortran order picks the kernel); np.einsum sums in another order."""
    return np.matmul(mat, vec[..., None])[..., 0]


def dot(a: Arr, b: Arr) -> Arr:
    """Row-wise a . b over (..., n) by BLAS ddot, as the single-arm ``a @ b`` on vectors."""
    return np.matmul(a[..., None, :], b[..., :, None])[..., 0, 0]


@dataclass(frozen=True, eq=False)
class ArmTerms:
    """The nominal model at the measured state of N trials: what the control laws read."""

    q: Arr
    """(N, 7) measured joint angles [rad]."""
    dq: Arr
    """(N, 7) measured joint velocities [rad/s]."""
    pos: Arr
    """(N, 3) TCP position [m] (arm base frame)."""
    rot: Arr
    """(N, 3, 3) TCP rotation matrix."""
    jac: Arr
    """(N, 6, 7) TCP Jacobian, linear rows first."""
    jdot_dq: Arr
    """(N, 6) Jdot dq of the TCP."""
    mass: Arr
    """(N, 7, 7) joint-space inertia including rotor armature."""
    bias: Arr
    """(N, 7) c + g plus the model's viscous joint friction [N m]."""

    def take(self, ids: Ids) -> ArmTerms:
        """The terms of trials `ids` (a law evaluated on a subset of the batch)."""
        return ArmTerms(*(getattr(self, f)[ids] for f in self.__dataclass_fields__))


class BatchNominalArm:
    """N copies of the arm-only model, loaded with each trial's measured (q, dq) per period."""

    def __init__(self, n: int, model: mujoco.MjModel | None = None, nthread: int = 1) -> None:
        if n < 1:
            raise ConfigError(f"a batch needs n >= 1 trials, got {n}")
        self.n = n
        self.model = model if model is not None else build_arm_spec().compile()
        m = self.model
        self.index = ArmIndex.from_model(m)
        idx = self.index
        # Only kinematics, M and the bias forces are read: skipping collision, constraints,
        # sensors, actuation and passive forces halves a forward pass and changes none of them.
        fast = copy.copy(m)
        fast.opt.disableflags |= _UNUSED_STAGES
        # a trial's measured state, and its two mass-matrix probes q +- step for Mdot dq
        self.batch = Batch(fast, n, nthread)
        self._probe = Batch(fast, 2 * n, nthread)
        for b in (self.batch, self._probe):
            b.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)  # qpos0 off the arm, as a fresh MjData
        self._qpos, self._qvel = self.batch.bind("qpos"), self.batch.bind("qvel")
        self._probe_qpos = self._probe.bind("qpos")
        # outputs are registered before the first call (a field bound later reads zero until then)
        names = ("M", "qfrc_bias", "site_xpos", "site_xmat", "cdof", "cdof_dot", "cvel",
                 "subtree_com")
        self._out = {f: self.batch.bind(f) for f in names}
        self._probe_mass = self._probe.bind("M")
        self._gather = _arm_mass_gather(m, idx)
        site = idx.tcp_site
        self._body = int(m.site_bodyid[site])
        self._root = int(m.body_rootid[self._body])
        self._chain = _arm_columns(m, self._body, idx)
        self._armature = np.diag(m.dof_armature[idx.dof])
        self._damping = m.dof_damping[idx.dof].copy()
        self.q = np.zeros((n, N_JOINTS))
        self.dq = np.zeros((n, N_JOINTS))

    def load(self, q: Arr, dq: Arr) -> None:
        """Forward kinematics, mass matrix and bias forces of every trial at its (q, dq)."""
        q, dq = np.asarray(q, dtype=float), np.asarray(dq, dtype=float)
        if q.shape != (self.n, N_JOINTS) or dq.shape != (self.n, N_JOINTS):
            raise ConfigError(f"load needs q and dq of shape ({self.n}, {N_JOINTS}), got "
                              f"{q.shape} and {dq.shape}")
        self.q[:], self.dq[:] = q, dq
        self._qpos[:, self.index.qpos] = q
        self._qvel[:, self.index.dof] = dq
        self.batch.forward(stage=mujoco.mjtStage.mjSTAGE_VEL)  # as load(): up to mj_rne(flg_acc=0)

    def tcp_pose(self) -> tuple[Arr, Arr]:
        """(N, 3) TCP positions [m] and (N, 3, 3) rotation matrices."""
        s = self.index.tcp_site
        return (self._out["site_xpos"][:, s].copy(),
                self._out["site_xmat"][:, s].reshape(self.n, 3, 3).copy())

    def _offset(self) -> Arr:
        """TCP minus the root subtree's centre of mass, as mj_jac and mj_jacDot take it."""
        return self._out["site_xpos"][:, self.index.tcp_site] - self._out["subtree_com"][:, self._root]

    def tcp_jacobian(self) -> Arr:
        """(N, 6, 7) TCP Jacobians: mj_jac's cdof_lin + cdof_ang x offset per arm dof."""
        cdof = self._out["cdof"][:, self._chain]  # (N, 7, 6)
        lin = cdof[..., 3:] + cross(cdof[..., :3], self._offset()[:, None])
        return np.concatenate([lin, cdof[..., :3]], axis=2).transpose(0, 2, 1).copy()

    def tcp_jacobian_dot(self) -> Arr:
        """(N, 6, 7) time derivative of the TCP Jacobian, mj_jacDot's sums (hinge joints only:
        no ball or free joint in the arm, so cdof_dot is the stored one)."""
        offset = self._offset()
        cdof = self._out["cdof"][:, self._chain]
        cdot = self._out["cdof_dot"][:, self._chain]
        cvel = self._out["cvel"][:, self._body]
        # the TCP's velocity (mju_transformSpatial of the body's cvel to the point)
        pvel = cvel[:, 3:] - cross(offset, cvel[:, :3])
        lin = (cdot[..., 3:] + cross(cdot[..., :3], offset[:, None])) + cross(cdof[..., :3],
                                                                                 pvel[:, None])
        # each (6, 7) in Fortran order, the layout of NominalArm's column gather: np.matmul then
        # takes the same gemv kernel for Jdot dq
        return np.concatenate([lin, cdot[..., :3]], axis=2).transpose(0, 2, 1)

    def mass(self) -> Arr:
        """(N, 7, 7) arm block of M with armature: the sparse lower triangle, mirrored."""
        # C order as mj_fullM's block: a gather's own layout sends np.matmul to another kernel
        return np.ascontiguousarray(self._out["M"][:, self._gather])

    def link_mass(self) -> Arr:
        """(N, 7, 7) link-side inertia (the torque sensors read after the gearbox)."""
        return self.mass() - self._armature

    def rne_bias(self) -> Arr:
        """(N, 7) MuJoCo's bias force n = C dq + g (mj_rne without acceleration)."""
        return self._out["qfrc_bias"][:, self.index.dof]

    def bias(self) -> Arr:
        """(N, 7) n plus the model's viscous joint friction, as ``NominalArm.bias``."""
        return self.rne_bias() + self._damping * self._qvel[:, self.index.dof]

    def terms(self) -> ArmTerms:
        """Everything the laws read, at the loaded state."""
        pos, rot = self.tcp_pose()
        return ArmTerms(self.q.copy(), self.dq.copy(), pos, rot, self.tcp_jacobian(),
                        mat_vec(self.tcp_jacobian_dot(), self.dq), self.mass(), self.bias())

    def momentum(self) -> Arr:
        """(N, 7) p = M_link dq [N m s]."""
        return mat_vec(self.link_mass(), self.dq)

    def mass_dot_dq(self) -> Arr:
        """(N, 7) Mdot dq by ``MomentumTerms``' central difference of M along dq (zero at rest)."""
        dq = self.dq
        speed = np.sqrt(dot(dq, dq))
        moving = speed != 0.0
        # a resting trial probes at q itself and reads zero below
        step = MDOT_STEP_RAD * dq / np.where(moving, speed, 1.0)[:, None]
        step[~moving] = 0.0
        n, qadr = self.n, self.index.qpos
        self._probe_qpos[:n, qadr] = self.q + step
        self._probe_qpos[n:, qadr] = self.q - step
        self._probe.forward(stage=mujoco.mjtStage.mjSTAGE_POS)
        full = np.ascontiguousarray(self._probe_mass[:, self._gather])
        out = mat_vec(full[:n] - full[n:], dq) * (speed / (2 * MDOT_STEP_RAD))[:, None]
        out[~moving] = 0.0
        return out

    def beta(self) -> Arr:
        """(N, 7) beta = n - Mdot dq, the momentum observer's model term [N m]."""
        return self.rne_bias() - self.mass_dot_dq()


def _arm_mass_gather(m: mujoco.MjModel, idx: ArmIndex) -> Ids:
    """(7, 7) addresses into MjData.M (CSR lower triangle: M_rownnz, M_rowadr, M_colind) of
    the arm block, each off-diagonal element read for both triangles as mj_fullM mirrors it."""
    col = {int(d): k for k, d in enumerate(idx.dof)}
    out = np.full((len(idx.dof), len(idx.dof)), -1, dtype=np.intp)
    for i, row in enumerate(idx.dof):
        start = int(m.M_rowadr[row])
        for adr in range(start, start + int(m.M_rownnz[row])):
            j = col.get(int(m.M_colind[adr]))
            if j is not None:
                out[i, j] = out[j, i] = adr
    if (out < 0).any():
        raise ConfigError("the arm's mass-matrix block is not dense in the model's sparse M")
    return out


def _arm_columns(m: mujoco.MjModel, body: int, idx: ArmIndex) -> Ids:
    """The arm dofs, checked to be hinges in the TCP body's ancestor chain (mj_jac's columns;
    mj_jacDot treats ball and free joints apart, which the arm has none of)."""
    weld = int(m.body_weldid[body])
    chain, i = set(), int(m.body_dofadr[weld] + m.body_dofnum[weld] - 1)
    while i >= 0:
        chain.add(i)
        i = int(m.dof_parentid[i])
    for d in idx.dof:
        if int(d) not in chain or m.jnt_type[m.dof_jntid[d]] != mujoco.mjtJoint.mjJNT_HINGE:
            raise ConfigError(f"arm dof {int(d)} must be a hinge that moves the TCP")
    return np.asarray(idx.dof, dtype=np.intp)
