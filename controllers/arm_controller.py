"""One arm in a compiled plant model: :class:`BatchArmController` at N = 1.

The controller exists once, over a batch axis (controllers/batch_*.py); the episode runs it with
a batch of one. This adapter samples the plant's sensors from its MjData, writes ``data.ctrl``,
and keeps one arm's interface: CartesianTarget / ForceTarget objects, (7,) arrays, floats. It
runs at ``rate_hz`` over the physics substeps (1 kHz over 0.1 ms steps = 10 substeps).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_config import ArmControllerConfig, ControlLaw, controller_config
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.controllers.arm_model import NominalArm, require_joint_target
from serpar.controllers.arm_sensors import ArmMeasurement
from serpar.controllers.batch_controller import BatchArmController, BatchSaturationRecord
from serpar.controllers.batch_laws import LAWS
from serpar.controllers.batch_sensors import BatchArmSensors, Seed
from serpar.errors import ConfigError
from serpar.sim.arm import HOME_Q
from serpar.sim.arm_drive import ArmIndex

__all__ = ["ArmController", "ArmControllerConfig", "ArmSensors", "ControlLaw",
           "SaturationRecord", "controller_config"]

Vec = NDArray[np.float64]
_DEFAULT_CONFIG = ArmControllerConfig()


def _strided(index: NDArray[np.int64]) -> slice | NDArray[np.int64]:
    """`index` as a slice when evenly spaced (the plant's torque sensors are every third
    sensordata entry): a view per period instead of a gather."""
    index = np.asarray(index)
    step = int(index[1] - index[0]) if len(index) > 1 else 1
    if step > 0 and np.array_equal(index, index[0] + step * np.arange(len(index))):
        return slice(int(index[0]), int(index[-1]) + 1, step)
    return index


class ArmSensors:
    """The arm's sensors in a plant MjData, read through the batch sensor model at N = 1."""

    def __init__(self, index: ArmIndex, sensors: BatchArmSensors) -> None:
        if sensors.n != 1:
            raise ConfigError(f"ArmSensors reads one arm, got a batch of {sensors.n}")
        self.index, self.batch, self.config = index, sensors, sensors.config
        self._qpos, self._dof, self._torque = (_strided(index.qpos), _strided(index.dof),
                                                    _strided(index.torque_adr))
        self._latched: Vec | None = None

    @property
    def bias(self) -> Vec:
        """The torque sensors' drifting bias now [N m]."""
        return self.batch.bias[0]

    def latch(self, torque: Vec) -> None:
        """The torque sensors' reading for the next read (the mean over the control period that
        just ended, from :class:`TorqueADC`); without it a read samples the torque MuJoCo
        computed at the start of the last physics substep."""
        self._latched = torque

    def sample(self, data: mujoco.MjData) -> tuple[Vec, Vec, Vec]:
        """The true (1, 7) q, dq and torque reading the sensor model reads (views, no copies)."""
        raw, self._latched = (data.sensordata[self._torque] if self._latched is None
                              else self._latched), None
        return data.qpos[None, self._qpos], data.qvel[None, self._dof], np.asarray(raw)[None]

    def read(self, model: mujoco.MjModel, data: mujoco.MjData, dt: float) -> ArmMeasurement:
        """Sample the sensors of the plant `data`; `dt` is the time since the last read."""
        meas = self.batch.read(*self.sample(data), dt)
        return ArmMeasurement(meas.q[0], meas.dq[0], meas.tau_J[0])


class SaturationRecord:
    """One arm's torque saturation: periods with any joint saturated, worst request per joint."""

    def __init__(self, record: BatchSaturationRecord) -> None:
        self.record = record

    @property
    def periods(self) -> int:
        return int(self.record.periods[0])

    @property
    def worst_ratio(self) -> Vec:
        return self.record.worst_ratio[0]

    def summary(self) -> str:
        return self.record.summary(0)


class ArmController:
    """One arm in a compiled plant model (prefix e.g. "arm/"); its sensor noise is the stream
    ``np.random.default_rng(seed)`` draws."""

    def __init__(self, model: mujoco.MjModel, prefix: str = "",
                 config: ArmControllerConfig = _DEFAULT_CONFIG, seed: Seed = 0) -> None:
        self.config = config
        self.index = ArmIndex.from_model(model, prefix)
        self.batch = BatchArmController(1, model.opt.timestep, config, seeds=[seed])
        self.substeps = self.batch.substeps
        """Physics steps per period; the cell runtime changes it with the timestep."""
        self.dt = self.batch.dt
        self.nominal = NominalArm(batch=self.batch.nominal)
        self.sensors = ArmSensors(self.index, self.batch.sensors)
        self.saturation = SaturationRecord(self.batch.saturation)
        self.cart_target: CartesianTarget | None = None
        self.force_target: ForceTarget | None = None
        self._q_posture: Vec | None = None
        self._actuators = _strided(self.index.actuators)

    # --- targets ---------------------------------------------------------------------------
    def hold_joints(self, q: Vec, dq: Vec | None = None) -> None:
        self.batch.hold_joints(require_joint_target(q), None if dq is None else np.asarray(dq, float))

    def track(self, target: CartesianTarget, law: ControlLaw = ControlLaw.IMPEDANCE,
              force: ForceTarget | None = None) -> None:
        """Cartesian target for the impedance or force-position law (force: along an axis)."""
        if law is ControlLaw.FORCE_POSITION and force is None:
            raise ConfigError("force_position needs a ForceTarget (axis, newtons)")
        if force is None:
            self.batch.track(target.pos, target.rot, target.vel, target.acc, law)
        else:
            self.batch.track(target.pos, target.rot, target.vel, target.acc, law, force.axis,
                             force.force, unit_axis=True)
        self.cart_target, self.force_target = target, force

    @property
    def law(self) -> ControlLaw:
        return LAWS[self.batch.law[0]]

    @property
    def q_posture(self) -> Vec | None:
        """Nullspace posture target of the Cartesian laws (None: HOME_Q)."""
        return self._q_posture

    @q_posture.setter
    def q_posture(self, q: Vec | None) -> None:
        self._q_posture = q
        self.batch.set_posture(HOME_Q if q is None else q)

    @property
    def force_offset(self) -> float:
        """The force-position reference's offset along the force axis [m]."""
        return float(self.batch.force_offset[0])

    def tare(self) -> None:
        """Zero the wrench estimate (TCP free of contact)."""
        self.batch.tare()

    @property
    def wrench(self) -> Vec:
        """Estimated wrench the environment applies at the TCP (force, torque)."""
        return self.batch.wrench[0]

    def measured_push(self) -> float:
        """F_s along the force axis: what the robot pushes on the environment with [N]."""
        return float(self.batch.measured_push()[0])

    @property
    def measurement(self) -> ArmMeasurement | None:
        """The last update's sensor readings."""
        meas = self.batch.measurement
        return None if meas is None else ArmMeasurement(meas.q[0], meas.dq[0], meas.tau_J[0])

    @property
    def tau(self) -> Vec:
        """The last update's saturated torques [N m]."""
        return self.batch.tau[0]

    # --- the 1 kHz update ------------------------------------------------------------------
    def update(self, model: mujoco.MjModel, data: mujoco.MjData) -> Vec:
        """Read sensors, compute the law's torques, saturate, write data.ctrl; returns tau."""
        tau = self.batch.update(*self.sensors.sample(data))[0]
        data.ctrl[self._actuators] = tau
        return tau

    def step(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """One control period: update, then the physics substeps."""
        self.update(model, data)
        mujoco.mj_step(model, data, nstep=self.substeps)
