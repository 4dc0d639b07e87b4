"""The controller's nominal arm for N trials at once (one arm: N = 1), one ``mujoco.batch.Batch``
call per period: kinematics, the TCP Jacobian and its derivative, the mass matrix, the bias
forces, and the momentum observer's terms.

The controller never reads the plant for its model terms: it loads the *measured* joint state
into its own arm-only model, as a real Panda controller evaluates libfranka's model from ``q``
and ``dq`` (plant and model come from the same MJCF: with noise off the model is exact). Every
term is read from fields the batch's forward pass computes (M, qfrc_bias, site pose, cdof,
cdof_dot, cvel, subtree_com) and combined with the arithmetic of the MuJoCo functions one MjData
would be asked for (mj_fullM, mj_jacSite, mj_jacDot), in their operation order: a trial's terms
are theirs bit for bit (tests/test_batch_controller.py).

The momentum observer (controllers/wrench.py) works on the link-side dynamics (the torque
sensors sit after the gearbox: no rotor armature, no motor-side damping; assets/arm/README.md),
M(q) ddq + C(q, dq) dq + g(q) = tau_J + tau_ext. The momentum p = M(q) dq changes as
dp/dt = M ddq + Mdot dq, and with Mdot = C + C^T (the Christoffel C, Mdot - 2C skew)

    dp/dt = tau_J + tau_ext + C^T dq - g = tau_J + tau_ext - beta,
    beta = g - C^T dq = n - Mdot dq,       n = C dq + g (MuJoCo's bias force, mj_rne).

So it needs n, which the model has at the measured state, and Mdot dq, the derivative of M along
the motion: a central difference of M at q -+ eps dq/|dq| (two mass matrices per trial on a probe
batch, so the loaded state stays the measured one). No acceleration is ever formed.
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import mujoco
import numpy as np
from mujoco.batch import Batch
from numpy.typing import NDArray

from serpar.controllers.batch_linalg import dot, mat_vec
from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS, build_arm_spec
from serpar.sim.arm_drive import ArmIndex

Arr = NDArray[np.float64]
Ids = NDArray[np.intp]

MDOT_STEP_RAD = 1e-5
"""Joint-space step of the central difference of M along dq [rad]: its truncation error
(~step^2 times M's third derivative) and round-off (~1e-16 / step) both stay below 1e-9."""

# a x b's two products per component, (a1 b2, a2 b0, a0 b1) and (a2 b1, a0 b2, a1 b0), gathered
# in one ndarray.take each (a third of a fancy index's cost on small arrays): four numpy calls
# where a gather per factor and product took seven
_CROSS_A = np.array([[1, 2, 0], [2, 0, 1]])
_CROSS_B = _CROSS_A[::-1].copy()
# _jacobians' crosses: rows of the stacked (cdof, cdof_dot) motions (14 x 6, flattened) and of
# the stacked (offset, pvel) points (2 x 3) each of the 21 crosses takes its factors from
_JAC_ROWS = np.r_[0:N_JOINTS, N_JOINTS:2 * N_JOINTS, 0:N_JOINTS]
_JAC_CROSS_A = _JAC_ROWS[:, None, None] * 6 + _CROSS_A
_JAC_CROSS_B = np.repeat([0, 1], [2 * N_JOINTS, N_JOINTS])[:, None, None] * 3 + _CROSS_B
_DISABLE = mujoco.mjtDisableBit
_UNUSED_STAGES = int(_DISABLE.mjDSBL_CONSTRAINT | _DISABLE.mjDSBL_SENSOR
                     | _DISABLE.mjDSBL_ACTUATION | _DISABLE.mjDSBL_SPRING | _DISABLE.mjDSBL_DAMPER)


def cross(a: Arr, b: Arr) -> Arr:
    """Row-wise a x b over (..., 3) in mju_cross's operation order (a1 b2 - a2 b1, ...)."""
    p = a.take(_CROSS_A, axis=-1) * b.take(_CROSS_B, axis=-1)
    return p[..., 0, :] - p[..., 1, :]


class ArmTerms(NamedTuple):
    """The nominal model at the measured state of N trials: what the control laws read (a
    NamedTuple: built every period, a third of a frozen dataclass's cost)."""

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
    jdot_dq: Arr | None
    """(N, 6) Jdot dq of the TCP; None when only joint-space laws run (not computed)."""
    mass: Arr
    """(N, 7, 7) joint-space inertia including rotor armature (what the motors accelerate)."""
    bias: Arr
    """(N, 7) c + g plus the model's viscous joint friction (compensated like Franka's friction
    observer) [N m]: what the motors must supply at rest acceleration."""

    def take(self, ids: Ids) -> ArmTerms:
        """The terms of trials `ids` (a law evaluated on a subset of the batch)."""
        return ArmTerms(*(None if v is None else v[ids] for v in self))


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
        qpos, qvel, probe = self.batch.bind("qpos"), self.batch.bind("qvel"), self._probe.bind("qpos")
        qsel, dsel = _run(idx.qpos, "qpos"), _run(idx.dof, "dof")
        _check_hinge_chain(m, int(m.site_bodyid[idx.tcp_site]), idx)  # mj_jac's columns
        # views of the bound arrays, which the batch reads and refills in place every call:
        # what each period writes and reads is indexed once, here
        self._arm_qpos, self._arm_qvel = qpos[:, qsel], qvel[:, dsel]
        self._probe_plus, self._probe_minus = probe[:n, qsel], probe[n:, qsel]
        # outputs are registered before the first call (a field bound later reads zero until then)
        names = ("M", "qfrc_bias", "site_xpos", "site_xmat", "cdof", "cdof_dot", "cvel",
                 "subtree_com")
        out = {f: self.batch.bind(f) for f in names}
        self._mass_out, self._probe_mass = out["M"], self._probe.bind("M")
        self._gather = _arm_mass_gather(m, idx)
        site = idx.tcp_site
        body = int(m.site_bodyid[site])
        self._site_pos = out["site_xpos"][:, site]
        self._site_mat = out["site_xmat"].reshape(n, -1, 3, 3)[:, site]
        self._root_com = out["subtree_com"][:, int(m.body_rootid[body])]
        cdof, cdot, cvel = out["cdof"][:, dsel], out["cdof_dot"][:, dsel], out["cvel"][:, body]
        self._cdof, self._cdot = cdof, cdot  # (N, 7, 6): angular, linear
        self._cdof_ang, self._cdof_lin = cdof[..., :3], cdof[..., 3:]
        self._cdot_ang, self._cdot_lin = cdot[..., :3], cdot[..., 3:]
        self._cvel_ang, self._cvel_lin = cvel[:, :3], cvel[:, 3:]
        self._rne = out["qfrc_bias"][:, dsel]
        self._armature = np.diag(m.dof_armature[idx.dof])
        self._damping = m.dof_damping[idx.dof].copy()
        self.q = np.zeros((n, N_JOINTS))
        self.dq = np.zeros((n, N_JOINTS))

    def load(self, q: Arr, dq: Arr, adopt: bool = False) -> None:
        """Forward kinematics, mass matrix and bias forces of every trial at its (q, dq);
        `adopt`: keep the arrays themselves, the caller's to give away (never written after)."""
        # kept, and replaced (never written) by the next load: the terms hold them. C order
        # always: a plant's gathered columns can come Fortran-ordered, and a strided dq would
        # send np.matmul to another BLAS path (other round-off) than a single arm's vector.
        if adopt:
            q, dq = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(dq, dtype=float)
        else:
            q, dq = np.array(q, dtype=float, order="C"), np.array(dq, dtype=float, order="C")
        if q.shape != (self.n, N_JOINTS) or dq.shape != (self.n, N_JOINTS):
            raise ConfigError(f"load needs q and dq of shape ({self.n}, {N_JOINTS}), got "
                              f"{q.shape} and {dq.shape}")
        self.q, self.dq = q, dq
        self._arm_qpos[:] = q
        self._arm_qvel[:] = dq
        self.batch.forward(stage=mujoco.mjtStage.mjSTAGE_VEL)  # up to mj_rne without acceleration

    def tcp_pose(self) -> tuple[Arr, Arr]:
        """(N, 3) TCP positions [m] and (N, 3, 3) rotation matrices."""
        return self._site_pos.copy(), self._site_mat.copy()

    def _jacobians(self, with_dot: bool) -> tuple[Arr, Arr | None]:
        """(N, 6, 7) TCP Jacobians, mj_jac's cdof_lin + cdof_ang x offset per arm dof, and with
        `with_dot` their time derivatives, mj_jacDot's sums (hinge joints only: no ball or free
        joint in the arm, so cdof_dot is the stored one)."""
        # TCP minus the root subtree's centre of mass, as mj_jac and mj_jacDot take it
        offset = self._site_pos - self._root_com
        if not with_dot:
            return _c_order(self._cdof_lin + cross(self._cdof_ang, offset[:, None]),
                            self._cdof_ang), None
        # the TCP's velocity (mju_transformSpatial of the body's cvel to the point)
        pvel = self._cvel_lin - cross(offset, self._cvel_ang)
        # the three crosses per dof in one product (as cross(): rows 0-6 cdof_ang x offset, 7-13
        # cdof_dot_ang x offset, 14-20 cdof_ang x pvel), each factor gathered by one take
        motion = np.concatenate([self._cdof, self._cdot], axis=1).reshape(self.n, -1)
        p = (motion.take(_JAC_CROSS_A, axis=1)
             * np.concatenate([offset, pvel], axis=1).take(_JAC_CROSS_B, axis=1))
        arm = p[..., 0, :] - p[..., 1, :]
        jac = _c_order(self._cdof_lin + arm[:, :N_JOINTS], self._cdof_ang)
        lin = (self._cdot_lin + arm[:, N_JOINTS:2 * N_JOINTS]) + arm[:, 2 * N_JOINTS:]
        # each (6, 7) in Fortran order, the layout of a single Jacobian's column gather: np.matmul
        # then takes the same gemv kernel for Jdot dq
        return jac, np.concatenate([lin, self._cdot_ang], axis=2).transpose(0, 2, 1)

    def tcp_jacobian(self) -> Arr:
        """(N, 6, 7) TCP Jacobians, linear rows first."""
        return self._jacobians(False)[0]

    def tcp_jacobian_dot(self) -> Arr:
        """(N, 6, 7) time derivatives of the TCP Jacobians at the loaded (q, dq)."""
        jdot = self._jacobians(True)[1]
        assert jdot is not None
        return jdot

    def mass(self) -> Arr:
        """(N, 7, 7) arm block of M with armature: the sparse lower triangle, mirrored (a gather
        is C order, the layout of mj_fullM's block: np.matmul's kernel depends on it)."""
        return self._mass_out.take(self._gather, axis=1)

    def link_mass(self) -> Arr:
        """(N, 7, 7) link-side inertia (the torque sensors read after the gearbox: the reflected
        rotor inertia is not theirs)."""
        return self.mass() - self._armature

    def rne_bias(self) -> Arr:
        """(N, 7) MuJoCo's bias force n = C dq + g (mj_rne without acceleration)."""
        return self._rne.copy()  # a view of the live output

    def bias(self) -> Arr:
        """(N, 7) n plus the model's viscous joint friction (MJCF damping) at dq [N m]."""
        return self._rne + self._damping * self.dq

    def terms(self, jdot: bool = True) -> ArmTerms:
        """Everything the laws read, at the loaded state (`jdot`: Jdot dq too, which only the
        Cartesian laws read)."""
        pos, rot = self.tcp_pose()
        jac, jac_dot = self._jacobians(jdot)
        jdot_dq = None if jac_dot is None else mat_vec(jac_dot, self.dq)
        return ArmTerms(self.q, self.dq, pos, rot, jac, jdot_dq, self.mass(), self.bias())

    def momentum(self, mass: Arr | None = None) -> Arr:
        """(N, 7) p = M_link dq [N m s]; `mass`: this state's :meth:`mass`, if already read."""
        return mat_vec((self.mass() if mass is None else mass) - self._armature, self.dq)

    def mass_dot_dq(self) -> Arr:
        """(N, 7) Mdot dq = (d/ds M(q + s dq)) dq at s = 0, by a central difference (zero at
        rest; armature is in both probes and cancels)."""
        q, dq = self.q, self.dq
        speed = np.sqrt(dot(dq, dq))
        moving = None
        if speed.all():
            step = MDOT_STEP_RAD * dq / speed[:, None]
        else:  # a resting trial probes at q itself and reads zero below
            moving = speed != 0.0
            step = MDOT_STEP_RAD * dq / np.where(moving, speed, 1.0)[:, None]
            step[~moving] = 0.0
        np.add(q, step, out=self._probe_plus)  # in place: views of the probes' states
        np.subtract(q, step, out=self._probe_minus)
        self._probe.forward(stage=mujoco.mjtStage.mjSTAGE_POS)
        # M(q + step) - M(q - step) on the sparse rows, then mirrored: the same differences
        diff = self._probe_mass[:self.n] - self._probe_mass[self.n:]
        out = mat_vec(diff.take(self._gather, axis=1), dq) * (speed / (2 * MDOT_STEP_RAD))[:, None]
        if moving is not None:
            out[~moving] = 0.0
        return out

    def beta(self) -> Arr:
        """(N, 7) beta = n - Mdot dq = g - C^T dq, the momentum observer's model term [N m]."""
        return self._rne - self.mass_dot_dq()


def _c_order(lin: Arr, ang: Arr) -> Arr:
    """(N, 6, 7) C-order Jacobians from (N, 7, 3) linear and angular columns: the layout of
    mj_jacSite's rows, which np.matmul's kernel choice depends on (np.concatenate of transposed
    inputs would keep their column order)."""
    return np.concatenate([lin, ang], axis=2).transpose(0, 2, 1).copy()


def _run(index: NDArray[np.int64], what: str) -> slice:
    """The arm's `what` addresses as a slice: a contiguous run, so the hot path reads views."""
    start = int(index[0])
    if not np.array_equal(index, np.arange(start, start + len(index))):
        raise ConfigError(f"the arm's {what} addresses {index} must be one contiguous run")
    return slice(start, start + len(index))


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


def _check_hinge_chain(m: mujoco.MjModel, body: int, idx: ArmIndex) -> None:
    """The arm dofs must be hinges in the TCP body's ancestor chain: then the Jacobians' columns
    are their cdofs (mj_jacDot treats ball and free joints apart, which the arm has none of)."""
    weld = int(m.body_weldid[body])
    chain, i = set(), int(m.body_dofadr[weld] + m.body_dofnum[weld] - 1)
    while i >= 0:
        chain.add(i)
        i = int(m.dof_parentid[i])
    for d in idx.dof:
        if int(d) not in chain or m.jnt_type[m.dof_jntid[d]] != mujoco.mjtJoint.mjJNT_HINGE:
            raise ConfigError(f"arm dof {int(d)} must be a hinge that moves the TCP")
