"""The arm's sensors for N trials, each trial with its own random stream.

Trial i draws from ``SeedSequence(seed, spawn_key=(i,))`` (numpy's i-th spawned child of
``seed``), so its noise is the same whether it runs alone, in a batch of 7 or of 1000, on any
thread count or machine. A stream is consumed in one fixed order (the bias at start-up, then
per read the bias walk, the torque noise and the velocity noise, each channel only when its
sigma is positive): the order the one-arm sensor model drew in before it became this at N = 1,
so an arm seeded with SeedSequence(seed) (``np.random.default_rng(seed)``'s stream) reads the
noise it read then, bit for bit (tests/test_arm_controller_reference.py). The normals are drawn
K periods at a time, so the Python loop over trials runs once every K periods, never within one.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

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


class BatchMeasurement(NamedTuple):
    q: Arr
    """(N, 7) encoder angles [rad]."""
    dq: Arr
    """(N, 7) joint velocities [rad/s]."""
    tau_J: Arr
    """(N, 7) link-side joint torques [N m]."""


class BatchArmSensors:
    """The arm's sensor model for N trials (bias drift, noise, quantisation; one arm: N = 1)."""

    def __init__(self, config: ArmSensorConfig, seeds: Sequence[Seed], chunk: int = 100) -> None:
        if chunk < 1:
            raise ConfigError(f"chunk={chunk} must be >= 1 control period")
        if len(seeds) < 1:
            raise ConfigError("BatchArmSensors needs a seed per trial, got none")
        self.config, self.n, self.chunk = config, len(seeds), chunk
        # per read, in the drawing order: bias walk, torque noise, velocity noise
        sigmas = (config.torque_bias_walk, config.torque_noise_std, config.velocity_noise_std)
        self._live = tuple(s > 0 for s in sigmas)
        self._width = N_JOINTS * sum(self._live)
        # the constant sigmas are applied once per chunk (the same products a read would form);
        # the walk's depends on the read's dt and stays per read
        scales = (1.0, config.torque_noise_std, config.velocity_noise_std)
        self._scale = np.repeat([s for s, live in zip(scales, self._live) if live], N_JOINTS)
        self._rngs: list[np.random.Generator] = [np.random.default_rng(0)] * self.n  # reseed() below
        self.bias = np.zeros((self.n, N_JOINTS))
        self._draws = np.zeros((self.n, chunk, self._width))
        # one cursor for all trials: a trial started mid-chunk gets its first normals from there
        self._cursor = chunk
        self._dt = float("nan")
        self._walk_step = 0.0
        self.reseed(np.arange(self.n), seeds)

    def reseed(self, slots: NDArray[np.intp], seeds: Sequence[Seed]) -> None:
        """Start new trials in `slots` (a fresh stream and start-up bias each)."""
        if len(slots) != len(seeds):
            raise ConfigError(f"{len(slots)} slots but {len(seeds)} seeds")
        for slot, seed in zip(slots, seeds):
            rng = np.random.Generator(np.random.PCG64(seed))
            self._rngs[slot] = rng
            self.bias[slot] = rng.normal(0.0, self.config.torque_bias_std, N_JOINTS)
            if self._cursor < self.chunk:  # a Generator's normals come in the same sequence
                self._fill(rng, self._draws[slot, self._cursor:])  # however they are grouped

    def _fill(self, rng: np.random.Generator, rows: Arr) -> None:
        rng.standard_normal(out=rows)
        rows *= self._scale

    def _next(self) -> Arr:
        """(N, width) this read's scaled normals, each trial's next from its own stream."""
        if self._cursor == self.chunk:  # once every `chunk` reads
            for slot, rng in enumerate(self._rngs):
                self._fill(rng, self._draws[slot])
            self._cursor = 0
        self._cursor += 1
        return self._draws[:, self._cursor - 1]

    def read(self, q: Arr, dq: Arr, tau: Arr, dt: float) -> BatchMeasurement:
        """Sample the sensors of the true (N, 7) q, dq and link-side torque; `dt` is the time
        since the last read."""
        cfg = self.config
        walk, tau_noise, dq_noise = self._live
        z = self._next() if self._width else self._draws[:, 0]  # ideal sensors: no draws
        k = 0  # the next channel's first column in z
        if walk:
            if dt != self._dt:
                self._dt, self._walk_step = dt, cfg.torque_bias_walk * np.sqrt(dt)
            self.bias += self._walk_step * z[:, :N_JOINTS]
            k += N_JOINTS
        out_tau = tau + self.bias
        if tau_noise:
            out_tau += z[:, k:k + N_JOINTS]
            k += N_JOINTS
        out_dq = dq + z[:, k:k + N_JOINTS] if dq_noise else np.array(dq, dtype=float)
        return BatchMeasurement(quantise(np.asarray(q, dtype=float), cfg.encoder_counts_per_rev),
                                out_dq, out_tau)
