"""What the real arm measures: encoder angles, joint velocities and link-side joint torques.
The noise model itself runs over a batch axis (controllers/batch_sensors.py; one arm reads it at
N = 1 through ``serpar.controllers.arm_controller.ArmSensors``); here its configuration, one
arm's measurement and the torque sensors' integrating ADC.

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
from serpar.sim.arm import TORQUE_AXIS
from serpar.sim.arm_drive import ArmIndex

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


class TorqueADC:
    """The joint torque sensors' integrating ADC: the mean over each control period.

    MuJoCo's semi-implicit step is a leapfrog: the torque computed at the start of substep n
    acts on the motion as if centred on t_n, and the sensors sample it there. The runtime
    centres each command switch on the period's start t_k (the first substep gets the mean of
    the old and new command), so that sample is the mean of the torques either side of the
    switch, while the period [t_k, t_k+1] holds only the new command. The period mean is the
    trapezoid over the substep starts with each end taken from its own side: the start
    extrapolated back from the samples after it, the end (not yet sampled when the next
    command is chosen) forward from the samples before it, both linearly over 0.1 ms
    (error ~ h^2 times the torque's curvature). With n substeps the weights are
    (0, 2, 1/2, 1, ..., 1, 1/2, 2) / n: centred on the period's middle, summing to one.
    A plain mean of the samples (or one sample) reads 25-50 us late or early against the
    period mean the diagnosis assumes (diagnosis/arm_dynamics_signals.py), which an
    effect-free episode then shows as sensor timing.

    A sensor with a MuJoCo ``delay`` of at least one step reads its history, linearly
    interpolated, ``delay`` ago: its command switches arrive inside the period, where the
    extrapolating ends would straddle them (at a 0.1 ms step a 0.712 ms lag then reads as
    0.709 ms, 0.817 ms as 0.796 ms). Its period is already in the past, so its mean is the
    plain trapezoid (1/2, 1, ..., 1, 1/2) / n over the delayed readings at the substep starts
    and the period's end, read from the history (``mj_readSensor`` at the end's time): exact
    for the interpolated history, whose switch ramps the trapezoid integrates exactly.

    Actuators with a ``delay`` of at least one step put their switches inside the period too,
    in what an undelayed sensor reads (a 0.85 ms actuation delay read 12.6 us early, 1.163 ms
    15.9 us late). The next command does not touch the torque at the period's end then, so
    the caller evaluates it (``mj_forward`` at the end's state, :attr:`reads_period_end`) and
    hands it to :meth:`end`; those sensors take the plain trapezoid as well."""

    def __init__(self, index: ArmIndex, substeps: int, model: mujoco.MjModel | None = None) -> None:
        if substeps < 4:
            raise ConfigError(f"TorqueADC needs >= 4 physics substeps per control period, got {substeps}")
        adr = np.asarray(index.torque_adr)
        stride = int(adr[1] - adr[0]) if len(adr) > 1 else 1
        # a strided view when the sensors are evenly spaced: read without a copy per substep
        self._even = len(adr) > 1 and stride > 0 and bool(np.all(np.diff(adr) == stride))
        self._adr, self._slice = adr, slice(int(adr[0]), int(adr[-1]) + 1, stride)
        w = np.ones(substeps)
        w[0] = 0.0
        w[1] += 1.0  # half the start value, extrapolated back: 2 x[1] - x[2], halved
        w[2] -= 0.5
        w[-1] += 1.0  # half the end value, extrapolated forward: 2 x[n-1] - x[n-2], halved
        w[-2] -= 0.5  # with 4 substeps both inner corrections fall on one sample: (0, 2, 0, 2) / 4
        self.weights = w / substeps
        """The weights of a sensor without delay (the batched trials use them)."""
        delay = (np.zeros(len(adr)) if model is None
                 else np.asarray(model.sensor_delay[np.asarray(index.torque_sensors)], float))
        self.delayed = np.flatnonzero(delay >= model.opt.timestep) if model is not None else np.zeros(0, int)
        """Sensors (joint indices) whose period mean is the delayed trapezoid."""
        late = (model is not None and bool(np.any(np.asarray(
            model.actuator_delay[np.asarray(index.actuators)]) >= model.opt.timestep)))
        self.at_end = (np.setdiff1d(np.arange(len(adr)), self.delayed) if late
                       else np.zeros(0, int))
        """Undelayed sensors of an arm whose actuators act late: their period end is read at
        the end's state (:meth:`end`)."""
        self._at_end_adr = adr[self.at_end]
        self._readings = substeps + (1 if self.at_end.size else 0)
        self._weights = np.repeat(self.weights[:, None], len(adr), axis=1)  # substep x sensor
        if self.delayed.size or self.at_end.size:
            trapezoid = np.ones(substeps)
            trapezoid[0] = 0.5
            self._weights[:, np.r_[self.delayed, self.at_end]] = (trapezoid / substeps)[:, None]
            sensors = np.asarray(index.torque_sensors)[self.delayed]
            self._ends = [(int(k), int(s), np.zeros(int(model.sensor_dim[s])))  # type: ignore[union-attr]
                          for k, s in zip(self.delayed, sensors)]
        self._end_weight = 0.5 / substeps
        self._sum = np.zeros(len(adr))
        self._n = 0

    def sample(self, data: mujoco.MjData, substep: int, model: mujoco.MjModel | None = None) -> None:
        """After physics substep `substep` (0-based) of the period: its start's torque (and,
        after the last, a delayed sensor's reading at the period's end, from ``model``'s
        history)."""
        reading = data.sensordata[self._slice] if self._even else data.sensordata[self._adr]
        if substep == 0:
            self._sum[:] = self._weights[0] * reading  # a new period starts
        else:
            self._sum += self._weights[substep] * reading
        if self.delayed.size and substep == len(self.weights) - 1:
            if model is None:
                raise ConfigError("TorqueADC: a delayed torque sensor's period end is read from "
                                  "the model's history; pass the model to sample()")
            for k, sensor, out in self._ends:
                value = mujoco.mj_readSensor(model, data, sensor, data.time, out, 1)
                self._sum[k] += self._end_weight * (out if value is None else value)[TORQUE_AXIS]
        self._n = substep + 1

    @property
    def reads_period_end(self) -> bool:
        """Whether the period's mean needs :meth:`end` after its last substep."""
        return bool(self.at_end.size)

    def end(self, data: mujoco.MjData) -> None:
        """The period's end for :attr:`at_end`: ``data`` evaluated (``mj_forward``) at the
        state after the last substep, before the next command."""
        self._sum[self.at_end] += self._end_weight * data.sensordata[self._at_end_adr]
        self._n += 1

    def mean(self) -> Vec | None:
        """The period's mean torque, or None before a whole period was sampled."""
        return self._sum.copy() if self._n == self._readings else None
