"""What the real arm measures: encoder angles, joint velocities and link-side joint torques.

Defaults (documented in assets/arm/README.md, "Sensors"):
- joint torque sensors: white noise sigma 0.02 N m, a constant bias drawn with sigma
  0.05 N m per joint at start-up and drifting as a random walk of 0.002 N m/sqrt(s)
  (strain-gauge thermal drift; the Panda's tau_J is specified to ~0.05 N m);
- encoders: quantisation 2 pi / 2^20 rad (a 20-bit absolute encoder on the link side);
- velocity: the drive's estimate, white noise sigma 1e-3 rad/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm_drive import ArmIndex, quantise

Vec = NDArray[np.float64]


@dataclass(frozen=True)
class ArmSensorConfig:
    """Noise magnitudes of the arm's sensors; :meth:`ideal` switches everything off."""

    torque_noise_std: float = 0.02
    """White noise on each tau_J sample [N m]."""
    torque_bias_std: float = 0.05
    """Spread of the per-joint torque bias drawn at start-up [N m]."""
    torque_bias_walk: float = 0.002
    """Random-walk intensity of the torque bias drift [N m / sqrt(s)]."""
    encoder_counts_per_rev: int = 2**20
    """Encoder resolution; 0 means no quantisation."""
    velocity_noise_std: float = 1e-3
    """White noise on each dq sample [rad/s]."""

    def __post_init__(self) -> None:
        for name in ("torque_noise_std", "torque_bias_std", "torque_bias_walk", "velocity_noise_std"):
            if not float(getattr(self, name)) >= 0:
                raise ConfigError(f"{name}={getattr(self, name)} must be >= 0")
        if self.encoder_counts_per_rev < 0:
            raise ConfigError(f"encoder_counts_per_rev={self.encoder_counts_per_rev} must be >= 0")

    @classmethod
    def ideal(cls) -> ArmSensorConfig:
        return cls(0.0, 0.0, 0.0, 0, 0.0)

    @property
    def is_ideal(self) -> bool:
        return self == ArmSensorConfig.ideal()


@dataclass(frozen=True, eq=False)
class ArmMeasurement:
    q: Vec
    dq: Vec
    tau_J: Vec


class ArmSensors:
    """Stateful sensor model (the bias drifts); one instance per simulated arm."""

    def __init__(self, index: ArmIndex, config: ArmSensorConfig = ArmSensorConfig(),
                 seed: int = 0) -> None:
        self.index, self.config = index, config
        self._rng = np.random.default_rng(seed)
        self.bias = self._rng.normal(0.0, config.torque_bias_std, len(index.dof))

    def read(self, model: mujoco.MjModel, data: mujoco.MjData, dt: float) -> ArmMeasurement:
        """Sample the sensors of the plant `data`; `dt` is the time since the last read."""
        cfg, idx, rng = self.config, self.index, self._rng
        n = len(idx.dof)
        if cfg.torque_bias_walk > 0:
            self.bias += rng.normal(0.0, cfg.torque_bias_walk * np.sqrt(dt), n)
        tau = data.sensordata[idx.torque_adr] + self.bias
        if cfg.torque_noise_std > 0:
            tau = tau + rng.normal(0.0, cfg.torque_noise_std, n)
        dq = data.qvel[idx.dof].copy()
        if cfg.velocity_noise_std > 0:
            dq += rng.normal(0.0, cfg.velocity_noise_std, n)
        return ArmMeasurement(quantise(data.qpos[idx.qpos], cfg.encoder_counts_per_rev), dq, tau)
