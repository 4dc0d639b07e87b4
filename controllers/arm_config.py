"""The arm controller's configuration: which law runs, its rate, sensors, wrench estimate and
gains. Its own module so the batch code (controllers/batch_*.py) and the one-arm adapter over it
(controllers/arm_controller.py, which re-exports these names) both import it without a cycle."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from serpar.controllers.arm_laws import ForcePositionGains, ImpedanceGains, JointGains
from serpar.controllers.arm_sensors import ArmSensorConfig
from serpar.controllers.wrench import WrenchEstimatorConfig
from serpar.errors import ConfigError


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


def controller_config(noise: bool) -> ArmControllerConfig:
    """The cell's arm controller: with the Panda's sensor noise, or with ideal sensors."""
    return ArmControllerConfig(sensors=ArmSensorConfig() if noise else ArmSensorConfig.ideal())
