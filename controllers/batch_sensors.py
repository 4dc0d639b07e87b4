"""The arm's sensors for N trials, each trial with its own random stream.

Trial i draws from ``SeedSequence(seed, spawn_key=(i,))`` (numpy's i-th spawned child of
``seed``), so its noise is the same whether it runs alone, in a batch of 7 or of 1000, on any
thread count or machine. A stream is consumed exactly as :class:`ArmSensors` consumes its
Generator (the bias at start-up, then per read the bias walk, the torque noise and the velocity
noise, each channel only when its sigma is positive): given the same SeedSequence a trial reads
what ``ArmSensors`` reads, bit for bit. The normals are drawn K periods at a time, so the Python
loop over trials runs once every K periods, never within one.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.controllers.arm_sensors import ArmSensorConfig
from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS
from serpar.sim.arm_drive import ArmIndex, quantise

Arr = NDArray[np.float64]
Seed = int | np.random.SeedSequence


def trial_seeds(seed: int, trials: Iterable[int]) -> list[np.random.SeedSequence]:
    """Each trial's stream: the trial-th child of `seed`, whatever else runs beside it."""
    return [np.random.SeedSequence(seed, spawn_key=(int(i),)) for i in trials]


def plant_arm_state(qpos: Arr, qvel: Arr, sensordata: Arr, index: ArmIndex) -> tuple[Arr, Arr, Arr]:
    """(N, 7) joint angles, velocities and torque-sensor readings of an arm in a plant batch's
    bound (N, ...) qpos, qvel and sensordata (what ``ArmSensors.read`` samples)."""
    return qpos[:, index.qpos], qvel[:, index.dof], sensordata[:, index.torque_adr]


@dataclass(frozen=True, eq=False)
class BatchMeasurement:
    q: Arr
    """(N, 7) encoder angles [rad]."""
    dq: Arr
    """(N, 7) joint velocities [rad/s]."""
    tau_J: Arr
    """(N, 7) link-side joint torques [N m]."""


class BatchArmSensors:
    """The sensor model of :class:`ArmSensors` for N trials (bias drift, noise, quantisation)."""

    def __init__(self, config: ArmSensorConfig, seeds: Sequence[Seed], chunk: int = 100) -> None:
        if chunk < 1:
            raise ConfigError(f"chunk={chunk} must be >= 1 control period")
        if len(seeds) < 1:
            raise ConfigError("BatchArmSensors needs a seed per trial, got none")
        self.config, self.n, self.chunk = config, len(seeds), chunk
        # per read, in ArmSensors' order: bias walk, torque noise, velocity noise
        sigmas = (config.torque_bias_walk, config.torque_noise_std, config.velocity_noise_std)
        self._live = tuple(s > 0 for s in sigmas)
        self._width = N_JOINTS * sum(self._live)
        self._rngs: list[np.random.Generator] = [np.random.default_rng(0)] * self.n  # reseed() below
        self.bias = np.zeros((self.n, N_JOINTS))
        self._draws = np.zeros((self.n, chunk, self._width))
        self._cursor = np.full(self.n, chunk)
        self.reseed(np.arange(self.n), seeds)

    def reseed(self, slots: NDArray[np.intp], seeds: Sequence[Seed]) -> None:
        """Start new trials in `slots` (a fresh stream and start-up bias each)."""
        if len(slots) != len(seeds):
            raise ConfigError(f"{len(slots)} slots but {len(seeds)} seeds")
        for slot, seed in zip(slots, seeds):
            rng = np.random.Generator(np.random.PCG64(seed))
            self._rngs[slot] = rng
            self.bias[slot] = rng.normal(0.0, self.config.torque_bias_std, N_JOINTS)
        self._cursor[slots] = self.chunk  # the next read draws their first chunk

    def _normals(self) -> Arr:
        """(N, width) standard normals of this read, each trial's next from its own stream."""
        if self._width == 0:
            return self._draws[:, 0]
        for slot in np.flatnonzero(self._cursor == self.chunk):  # once every `chunk` reads
            # a Generator's normals come in the same sequence however they are grouped
            self._draws[slot] = self._rngs[slot].standard_normal((self.chunk, self._width))
            self._cursor[slot] = 0
        z = self._draws[np.arange(self.n), self._cursor]
        self._cursor += 1
        return z

    def read(self, q: Arr, dq: Arr, tau: Arr, dt: float) -> BatchMeasurement:
        """Sample the sensors of the true (N, 7) q, dq and link-side torque; `dt` is the time
        since the last read."""
        cfg, z = self.config, self._normals()
        walk, tau_noise, dq_noise = self._live
        k = 0  # the next channel's first column in z
        if walk:
            self.bias += cfg.torque_bias_walk * np.sqrt(dt) * z[:, k:k + N_JOINTS]
            k += N_JOINTS
        out_tau = tau + self.bias
        if tau_noise:
            out_tau = out_tau + cfg.torque_noise_std * z[:, k:k + N_JOINTS]
            k += N_JOINTS
        out_dq = np.array(dq, dtype=float)
        if dq_noise:
            out_dq += cfg.velocity_noise_std * z[:, k:k + N_JOINTS]
        return BatchMeasurement(quantise(np.asarray(q, dtype=float), cfg.encoder_counts_per_rev),
                                out_dq, out_tau)
