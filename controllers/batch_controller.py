"""The arm controller for N trials: sensors -> nominal model -> wrench estimate -> laws ->
torques, each step one set of numpy operations over the batch (no Python loop over trials within
a control period; the sensors' streams refill every K periods). Trials may be in different laws
and phases: targets are set per trial through `ids`. It is the only implementation: one arm in a
plant MjData (the episode) is :class:`serpar.controllers.arm_controller.ArmController`, this at
N = 1.

It holds only what the pure laws cannot: the sensor model's drifting bias, the wrench filter,
the force-loop reference offsets and the saturation record. The plant is the caller's (a
``mujoco.batch.Batch`` in the Monte Carlo): ``update`` takes the true joint state and
torque-sensor readings as (N, 7) arrays and returns the saturated torques.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from serpar.controllers.arm_config import ArmControllerConfig, ControlLaw
from serpar.controllers.batch_laws import (
    LAW_CODE,
    BatchCartesianTarget,
    BatchForceTarget,
    BatchTargets,
    law_torque,
    laws_present,
    next_force_offset,
)
from serpar.controllers.batch_linalg import dot
from serpar.controllers.batch_model import BatchNominalArm
from serpar.controllers.batch_sensors import BatchArmSensors, BatchMeasurement, Seed, trial_seeds
from serpar.controllers.wrench import BatchWrenchEstimator
from serpar.errors import ConfigError, LimitError
from serpar.sim.arm import HOME_Q, N_JOINTS, Q_MAX, Q_MIN, TORQUE_LIMITS

Arr = NDArray[np.float64]
Ids = NDArray[np.intp]
_DOWN = np.array([0.0, 0.0, -1.0])
"""The axis F_s is read along without a force target."""
_DEFAULT_CONFIG = ArmControllerConfig()
_JOINT_PD, _FORCE_POSITION = LAW_CODE[ControlLaw.JOINT_PD], LAW_CODE[ControlLaw.FORCE_POSITION]
_LIMITS = np.asarray(TORQUE_LIMITS)
_NEG_LIMITS = -_LIMITS


class BatchSaturationRecord:
    """Torque saturation is reported, never silent: per trial the periods with any joint
    saturated and the worst request per joint (as a ratio of its limit)."""

    def __init__(self, n: int) -> None:
        self.periods = np.zeros(n, dtype=np.int64)
        self.worst_ratio = np.zeros((n, N_JOINTS))

    def saturate(self, tau: Arr) -> Arr:
        """`tau` clipped to the Panda torque limits, noted (np.minimum of np.maximum: np.clip's
        arithmetic without its Python wrapper)."""
        magnitude = np.abs(tau)
        self.periods += (magnitude > _LIMITS).any(axis=1)
        np.maximum(self.worst_ratio, magnitude / _LIMITS, out=self.worst_ratio)
        return np.minimum(np.maximum(tau, _NEG_LIMITS), _LIMITS)

    def summary(self, trial: int) -> str:
        if self.periods[trial] == 0:
            return "no torque saturation"
        worst = self.worst_ratio[trial]
        j = int(np.argmax(worst))
        return (f"torque saturated in {self.periods[trial]} control periods; worst joint{j + 1} "
                f"asked {worst[j]:.2f}x its limit")


class BatchArmController:
    """N arms, each in its own plant; trial i's sensor noise is stream `seeds[i]`
    (default: :func:`trial_seeds` of `seed` for trials 0..N-1)."""

    def __init__(self, n: int, timestep: float, config: ArmControllerConfig = _DEFAULT_CONFIG,
                 seed: int = 0, seeds: Sequence[Seed] | None = None, chunk: int = 100,
                 nthread: int = 1, model: mujoco.MjModel | None = None) -> None:
        seeds = trial_seeds(seed, range(n)) if seeds is None else seeds
        if len(seeds) != n:
            raise ConfigError(f"{n} trials need {n} seeds, got {len(seeds)}")
        self.n, self.config = n, config
        self.substeps = config.substeps(timestep)
        self.dt = self.substeps * timestep
        self.nominal = BatchNominalArm(n, model, nthread)
        self.sensors = BatchArmSensors(config.sensors, seeds, chunk)
        self.estimator = BatchWrenchEstimator(n, config.wrench)
        self.saturation = BatchSaturationRecord(n)
        self.law = np.full(n, LAW_CODE[ControlLaw.JOINT_PD], dtype=np.int8)
        self.q_target = np.zeros((n, N_JOINTS))
        self._q_target_set = np.zeros(n, dtype=bool)  # else the first measured q is held
        self.dq_target = np.zeros((n, N_JOINTS))
        self.cart_pos, self.cart_rot = np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1))
        self.cart_vel, self.cart_acc = np.zeros((n, 6)), np.zeros((n, 6))
        self.force_axis, self.force = np.tile(_DOWN, (n, 1)), np.zeros(n)
        self.has_force = np.zeros(n, dtype=bool)
        self.force_offset = np.zeros(n)
        self.q_posture = np.tile(np.asarray(HOME_Q), (n, 1))
        self._modes()
        self.measurement: BatchMeasurement | None = None
        self.tau = np.zeros((n, N_JOINTS))
        # views of the arrays above, which are only ever written in place
        self._targets = BatchTargets(self.law, self.q_target, self.dq_target,
                                     BatchCartesianTarget(self.cart_pos, self.cart_rot,
                                                          self.cart_vel, self.cart_acc),
                                     BatchForceTarget(self.force_axis, self.force),
                                     self.has_force, self.force_offset, self.q_posture)

    def restart(self, ids: ArrayLike, seeds: Sequence[Seed]) -> None:
        """New trials in slots `ids` with streams `seeds`: as a freshly built controller."""
        ids = self._ids(ids)
        self.sensors.reseed(ids, seeds)
        self.estimator.reset(ids)
        self.saturation.periods[ids], self.saturation.worst_ratio[ids] = 0, 0.0
        self.law[ids], self._q_target_set[ids] = LAW_CODE[ControlLaw.JOINT_PD], False
        for a in (self.q_target, self.dq_target, self.cart_pos, self.cart_vel, self.cart_acc,
                  self.force, self.force_offset, self.tau):
            a[ids] = 0.0
        self.cart_rot[ids], self.force_axis[ids], self.has_force[ids] = np.eye(3), _DOWN, False
        self.q_posture[ids] = HOME_Q
        self._modes()

    def _modes(self) -> None:
        """What the update needs to know of the trials' laws, worked out when they change (by
        hold_joints, track, restart: ``law`` is written through them only), not per period."""
        self._present = laws_present(self.law)
        self._fp = self.law == _FORCE_POSITION
        self._any_fp = _FORCE_POSITION in self._present
        self._cartesian = self._present != (_JOINT_PD,)  # Jdot dq is read by these laws only
        self._targets_set = bool(self._q_target_set.all())
        has = self.has_force[0]
        uniform = len(self._present) == 1 and bool((self.has_force == has).all())
        self._uniform = (self._present[0], bool(has)) if uniform else None

    def _ids(self, ids: ArrayLike | None) -> Ids:
        return np.arange(self.n) if ids is None else np.asarray(ids, dtype=np.intp).reshape(-1)

    # --- targets (per trial through ids; None: all) ------------------------------------------
    def hold_joints(self, q: ArrayLike, dq: ArrayLike | None = None,
                    ids: ArrayLike | None = None) -> None:
        ids = self._ids(ids)
        q = np.broadcast_to(np.asarray(q, dtype=float), (len(ids), N_JOINTS))
        bad = ~((q >= np.asarray(Q_MIN)) & (q <= np.asarray(Q_MAX)))  # NaN is out too
        if bad.any():
            t, j = np.argwhere(bad)[0]
            raise LimitError(f"trial {ids[t]}: joint{j + 1} target {q[t, j]:.4f} rad outside its "
                             f"limit [{Q_MIN[j]}, {Q_MAX[j]}] rad")
        self.law[ids] = LAW_CODE[ControlLaw.JOINT_PD]
        self.q_target[ids], self._q_target_set[ids] = q, True
        self.dq_target[ids] = 0.0 if dq is None else dq
        self._modes()

    def track(self, pos: ArrayLike, rot: ArrayLike, vel: ArrayLike | None = None,
              acc: ArrayLike | None = None, law: ControlLaw = ControlLaw.IMPEDANCE,
              force_axis: ArrayLike | None = None, force: ArrayLike | None = None,
              ids: ArrayLike | None = None, unit_axis: bool = False) -> None:
        """Cartesian targets (and a push of `force` newtons along `force_axis`) of trials `ids`
        for the impedance or force-position law; a new force task (another law, or no force
        target before) starts from the position reference. `unit_axis`: the caller vouches
        that the axes are unit vectors (a ForceTarget checked them)."""
        if law is ControlLaw.JOINT_PD:
            raise ConfigError("track() takes impedance or force_position; use hold_joints() for "
                              "joint_pd")
        has = force_axis is not None
        if has != (force is not None):
            raise ConfigError("a force target needs both force_axis and force")
        if law is ControlLaw.FORCE_POSITION and not has:
            raise ConfigError("force_position needs a force target (axis, newtons)")
        code = LAW_CODE[law]
        if ids is None and self._uniform is not None:
            # every trial in one law and force mode, the usual case of a target that moves each
            # period: the law bookkeeping is Python compares, only the targets are written
            was, had = self._uniform
            if was != code or not had:
                self.force_offset[:] = 0.0
            sel: slice | Ids = slice(None)
            switched = (was, had) != (code, has)
        else:
            sel = self._ids(ids)
            moved = self.law[sel] != code
            restart = moved | ~self.has_force[sel]
            self.force_offset[sel[restart]] = 0.0
            switched = bool(moved.any() | (self.has_force[sel] != has).any())
        if has:
            axis = np.asarray(force_axis, dtype=float)
            if not unit_axis:
                count = self.n if isinstance(sel, slice) else len(sel)
                BatchForceTarget.checked(np.broadcast_to(axis, (count, 3)), np.zeros(count))
            self.force_axis[sel], self.force[sel] = axis, force
        elif switched:  # no force target: F_s is read along -z, nothing fed forward
            self.force_axis[sel], self.force[sel] = _DOWN, 0.0
        self.cart_pos[sel], self.cart_rot[sel] = pos, rot
        self.cart_vel[sel] = 0.0 if vel is None else vel
        self.cart_acc[sel] = 0.0 if acc is None else acc
        if switched:
            self.law[sel], self.has_force[sel] = code, has
            self._modes()

    def set_posture(self, q: ArrayLike, ids: ArrayLike | None = None) -> None:
        """Nullspace posture target of trials `ids` (default HOME_Q)."""
        self.q_posture[self._ids(ids)] = q

    def tare(self, ids: ArrayLike | None = None) -> None:
        """Zero the wrench estimates of trials `ids` (TCP free of contact)."""
        self.estimator.tare(None if ids is None else self._ids(ids))

    @property
    def wrench(self) -> Arr:
        """(N, 6) estimated wrench the environment applies at each TCP."""
        return self.estimator.wrench

    def measured_push(self) -> Arr:
        """(N,) F_s along each trial's force axis [N]."""
        return dot(-self.force_axis, self.wrench[:, :3])

    def targets(self) -> BatchTargets:
        """The trials' laws and targets now (views of the controller's arrays)."""
        return self._targets

    # --- the 1 kHz update --------------------------------------------------------------------
    def update(self, q: Arr, dq: Arr, tau: Arr) -> Arr:
        """Read the sensors of the true (N, 7) joint state and link torques, compute each
        trial's law, saturate; returns the (N, 7) torques to apply."""
        meas = self.sensors.read(q, dq, tau, self.dt)
        self.measurement = meas
        nominal = self.nominal
        nominal.load(meas.q, meas.dq, adopt=True)  # the sensors' fresh arrays
        terms = nominal.terms(jdot=self._cartesian)
        self.estimator.update(nominal, terms, meas.tau_J, self.dt)
        if not self._targets_set:  # JOINT_PD without a target holds the first reading
            unset = ~self._q_target_set & (self.law == _JOINT_PD)
            self.q_target[unset], self._q_target_set[unset] = meas.q[unset], True
            self._targets_set = bool(self._q_target_set.all())
        has = self.has_force[0]
        uniform = len(self._present) == 1 and bool((self.has_force == has).all())
        self._uniform = (self._present[0], bool(has)) if uniform else None
        push = self.measured_push() if self._any_fp else None
        tau_cmd = law_torque(terms, self._targets, push, self.config, self._present)
        if push is not None:
            # elementwise, so computing every trial's and keeping the force-position ones' is exact
            offset = next_force_offset(self.force_offset, self._targets.force, push,
                                       self.config.force_position, self.dt)
            np.copyto(self.force_offset, offset, where=self._fp)
        self.tau = self.saturation.saturate(tau_cmd)
        return self.tau
