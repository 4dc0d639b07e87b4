"""The thin stateful wrapper: sensors -> nominal model -> wrench estimate -> law -> torques.

It holds only what the pure laws cannot: the sensor model's drifting bias, the wrench
filter, the force-loop reference offset and the saturation record. Runs at
``rate_hz`` over the physics substeps (1 kHz over 0.1 ms steps = 10 substeps).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_laws import (
    CartesianTarget,
    ForcePositionGains,
    ForceTarget,
    ImpedanceGains,
    JointGains,
    force_position_torque,
    impedance_torque,
    joint_pd_torque,
    next_force_offset,
)
from serpar.controllers.arm_model import NominalArm, require_joint_target
from serpar.controllers.arm_sensors import ArmMeasurement, ArmSensorConfig, ArmSensors
from serpar.controllers.wrench import WrenchEstimator, WrenchEstimatorConfig
from serpar.errors import ConfigError
from serpar.sim.arm import TORQUE_LIMITS
from serpar.sim.arm_drive import ArmIndex, saturate_torque

Vec = NDArray[np.float64]


class ControlLaw(enum.Enum):
    JOINT_PD = "joint_pd"
    IMPEDANCE = "impedance"
    FORCE_POSITION = "force_position"


@dataclass(frozen=True)
class ArmControllerConfig:
    rate_hz: float = 1000.0
    """Control rate (the Panda's 1 kHz torque interface)."""
    sensors: ArmSensorConfig = field(default_factory=ArmSensorConfig)
    wrench: WrenchEstimatorConfig = field(default_factory=WrenchEstimatorConfig)
    joint: JointGains = field(default_factory=JointGains)
    impedance: ImpedanceGains = field(default_factory=ImpedanceGains)
    force_position: ForcePositionGains = field(default_factory=ForcePositionGains)

    def __post_init__(self) -> None:
        if not self.rate_hz > 0:
            raise ConfigError(f"rate_hz={self.rate_hz} must be > 0")

    def substeps(self, timestep: float) -> int:
        """Physics steps per control period; the period must be a whole number of steps."""
        n = round(1.0 / (self.rate_hz * timestep))
        if n < 1 or abs(n * timestep * self.rate_hz - 1.0) > 1e-9:
            raise ConfigError(f"rate_hz={self.rate_hz} is not a whole number of {timestep} s "
                              f"physics steps; valid e.g. {1 / (10 * timestep):g} or "
                              f"{1 / (20 * timestep):g}")
        return n


@dataclass
class SaturationRecord:
    """Torque saturation is reported, never silent: count and worst request per joint."""

    periods: int = 0
    worst_ratio: NDArray[np.float64] = field(default_factory=lambda: np.zeros(7))

    def note(self, tau: Vec, limits: Vec, saturated: NDArray[np.bool_]) -> None:
        if saturated.any():
            self.periods += 1
        np.maximum(self.worst_ratio, np.abs(tau) / limits, out=self.worst_ratio)

    def summary(self) -> str:
        if self.periods == 0:
            return "no torque saturation"
        j = int(np.argmax(self.worst_ratio))
        return (f"torque saturated in {self.periods} control periods; worst joint{j + 1} asked "
                f"{self.worst_ratio[j]:.2f}x its limit")


class ArmController:
    """One arm in a compiled plant model (prefix e.g. "arm/")."""

    def __init__(self, model: mujoco.MjModel, prefix: str = "",
                 config: ArmControllerConfig = ArmControllerConfig(), seed: int = 0) -> None:
        self.config = config
        self.index = ArmIndex.from_model(model, prefix)
        self.substeps = config.substeps(model.opt.timestep)
        self.dt = self.substeps * model.opt.timestep
        self.nominal = NominalArm()
        self.sensors = ArmSensors(self.index, config.sensors, seed)
        self.estimator = WrenchEstimator(config.wrench)
        self.saturation = SaturationRecord()
        self._limits = np.asarray(TORQUE_LIMITS)
        self.law = ControlLaw.JOINT_PD
        self.q_target: Vec | None = None
        self.dq_target = np.zeros(7)
        self.cart_target: CartesianTarget | None = None
        self.force_target: ForceTarget | None = None
        self.force_offset = 0.0
        self.q_posture: Vec | None = None
        self.measurement: ArmMeasurement | None = None
        self.tau = np.zeros(7)

    # --- targets ---------------------------------------------------------------------------
    def hold_joints(self, q: Vec, dq: Vec | None = None) -> None:
        self.law = ControlLaw.JOINT_PD
        self.q_target = require_joint_target(q)
        self.dq_target = np.zeros(7) if dq is None else np.asarray(dq, dtype=float)

    def track(self, target: CartesianTarget, law: ControlLaw = ControlLaw.IMPEDANCE,
              force: ForceTarget | None = None) -> None:
        """Cartesian target for the impedance or force-position law (force: along an axis)."""
        if law is ControlLaw.JOINT_PD:
            raise ConfigError("track() takes impedance or force_position; use hold_joints() for "
                              "joint_pd")
        if law is ControlLaw.FORCE_POSITION and force is None:
            raise ConfigError("force_position needs a ForceTarget (axis, newtons)")
        if self.law is not law or self.force_target is None:
            self.force_offset = 0.0  # a new force task starts from the position reference
        self.law, self.cart_target, self.force_target = law, target, force

    def tare(self) -> None:
        """Zero the wrench estimate (TCP free of contact)."""
        self.estimator.tare()

    @property
    def wrench(self) -> Vec:
        """Estimated wrench the environment applies at the TCP (force, torque)."""
        return self.estimator.wrench

    def measured_push(self) -> float:
        """F_s along the force axis: what the robot pushes on the environment with [N]."""
        axis = self.force_target.axis if self.force_target is not None else np.array([0, 0, -1.0])
        return float(-axis @ self.wrench[:3])

    # --- the 1 kHz update ------------------------------------------------------------------
    def update(self, model: mujoco.MjModel, data: mujoco.MjData) -> Vec:
        """Read sensors, compute the law's torques, saturate, write data.ctrl; returns tau."""
        meas = self.sensors.read(model, data, self.dt)
        self.measurement = meas
        self.nominal.load(meas.q, meas.dq)
        self.estimator.update(self.nominal, meas.tau_J, self.dt)
        if self.law is ControlLaw.JOINT_PD:
            if self.q_target is None:
                self.q_target = meas.q.copy()
            tau = joint_pd_torque(self.nominal, self.q_target, self.dq_target, self.config.joint)
        elif self.law is ControlLaw.IMPEDANCE:
            ff = None
            if self.force_target is not None:  # Eq. 3's F_d: fed forward, never fed back
                ff = np.concatenate([self.force_target.force * self.force_target.axis, np.zeros(3)])
            tau = impedance_torque(self.nominal, self.cart_target, self.config.impedance, ff,
                                   self.q_posture)
        else:
            push = self.measured_push()
            tau = force_position_torque(self.nominal, self.cart_target, self.config.force_position,
                                        self.force_target, push, self.force_offset, self.q_posture)
            self.force_offset = next_force_offset(self.force_offset, self.force_target, push,
                                                  self.config.force_position, self.dt)
        tau_sat, saturated = saturate_torque(tau)
        self.saturation.note(tau, self._limits, saturated)
        self.tau = tau_sat
        data.ctrl[self.index.actuators] = tau_sat
        return tau_sat

    def step(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """One control period: update, then the physics substeps."""
        self.update(model, data)
        mujoco.mj_step(model, data, nstep=self.substeps)


def controller_config(noise: bool) -> ArmControllerConfig:
    """The cell's arm controller: with the Panda's sensor noise, or with ideal sensors."""
    return ArmControllerConfig(sensors=ArmSensorConfig() if noise else ArmSensorConfig.ideal())
