"""The "real" arm of the arm-dynamics twin: MuJoCo forward dynamics of a rigid-hand Panda with
whatever physics the twin adds, driven at 1 kHz by a joint-space tracking controller, read by
sensors with a realistic noise model.

Timing, as the diagnosis assumes it (diagnosis/arm_dynamics_signals.py):
- row k is the control period starting at t_k = k / rate;
- ``q``, ``dq`` are read at t_k (encoder quantisation, velocity noise);
- ``tau_J`` is the link-side torque sensor's mean over the period that ends at t_k (a strain
  gauge behind an integrating ADC; trapezoidal over the 0.1 ms physics substeps);
- ``tau_J_d`` is the command computed from the row's measurements and held over the period;
  the drive delivers it, ``delay`` later, with a white torque ripple per period.

MuJoCo's semi-implicit Euler step is a leapfrog: the force of substep n acts as an impulse
centred on t_n, so a torque switched at the start of substep n would act half a substep
(0.05 ms) early. The substep on which the applied torque jumps therefore gets the mean of the
old and the new torque: that puts the jump at t_n, to second order (without it a diagnosis
of an effect-free twin finds a latency of -0.05 ms, 3 sigma on 20 s).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS, Q_MAX, Q_MIN
from serpar.sim.arm_drive import ArmIndex, quantise, saturate_torque
from serpar.sim.physics import PhysicsConfig
from serpar.sim.rigid_arm import ArmDynamics

Vec = NDArray[np.float64]

CENTRE_Q: tuple[float, ...] = (0.0, -0.4, 0.0, -2.0, 0.0, 1.8, 0.785398)
"""Centre of the excitation: an elbow-up pose with the big joints carrying gravity load."""
AMPLITUDE: tuple[float, ...] = (0.7, 0.55, 0.6, 0.55, 0.9, 0.6, 1.0)
"""Peak excursion of each joint's sum of sines [rad]; stays 0.1 rad inside every limit."""
KP: tuple[float, ...] = (600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0)
KD: tuple[float, ...] = (15.0, 50.0, 15.0, 20.0, 10.0, 10.0, 5.0)
"""PD gains of the tracking loop: libfranka's joint impedance example with less damping on
joints 1, 3 and the wrist, so that the loop keeps its phase margin under 5 ms of actuation
latency. When joint 2 nears zero, joints 1 and 3 turn about nearly one axis and their
difference mode has only the rotors' inertia (~0.1 kg m^2): the example's 50 N m s/rad then
puts its crossover near 500 rad/s, and a 3.8 ms latency made it ring at 30-60 Hz and
saturate at 87 N m."""


@dataclass(frozen=True)
class SensorNoise:
    torque_std: float = 0.02
    """White noise of each tau_J sample [N m] (Panda order)."""
    torque_bias_std: float = 0.05
    """Start-up offset of each torque sensor [N m] (drawn; the diagnosis tares it)."""
    encoder_counts_per_rev: int = 2**20
    velocity_std: float = 1e-3
    actuation_std: float = 0.02
    """Torque ripple of the drive: white, per control period, about the command [N m]."""

    def __post_init__(self) -> None:
        for name in ("torque_std", "torque_bias_std", "velocity_std", "actuation_std"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"SensorNoise.{name}={getattr(self, name)} must be >= 0")
        if self.encoder_counts_per_rev < 0:
            raise ConfigError("SensorNoise.encoder_counts_per_rev must be >= 0")

    @property
    def encoder_sigma(self) -> float:
        """Quantisation noise of one encoder reading: step / sqrt(12) [rad]."""
        return 2 * np.pi / self.encoder_counts_per_rev / np.sqrt(12) if self.encoder_counts_per_rev else 0.0


@dataclass(frozen=True)
class Reality:
    """What the real arm has beyond the nominal model, outside its MjModel (sensors, drive)."""

    torque_gain: Vec = field(default_factory=lambda: np.zeros(N_JOINTS))
    """Relative gain error of each torque sensor (0.02 = reads 2 % high)."""
    torque_bias: Vec = field(default_factory=lambda: np.zeros(N_JOINTS))
    """Extra offset of each torque sensor [N m], on top of the start-up draw."""
    encoder_offset: Vec = field(default_factory=lambda: np.zeros(N_JOINTS))
    """Measured minus true joint angle [rad]."""
    delay: float = 0.0
    """Actuation latency: a command reaches the joint this much later [s]."""
    sensor_lag: float = 0.0
    """The torque sensors' readings belong to this much earlier than the encoders' [s]
    (a whole number of physics substeps)."""

    def __post_init__(self) -> None:
        for name in ("torque_gain", "torque_bias", "encoder_offset"):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (N_JOINTS,) or not np.all(np.isfinite(v)):
                raise ConfigError(f"Reality.{name} needs {N_JOINTS} finite values")
            object.__setattr__(self, name, v)
        if not 0.0 <= self.delay <= 0.02:
            raise ConfigError(f"Reality.delay={self.delay} s outside 0..0.02 s")
        if not 0.0 <= self.sensor_lag <= 0.005:
            raise ConfigError(f"Reality.sensor_lag={self.sensor_lag} s outside 0..0.005 s")


@dataclass(frozen=True)
class TwinRun:
    time: Vec
    q: Vec
    dq: Vec
    tau_J: Vec
    tau_J_d: Vec
    saturated: int
    """Samples at which some command hit the torque limit."""
    torque_offset: Vec
    """The torque sensors' total offset (start-up draw + the reality's) [N m]."""


def excitation(duration: float, rate: float, rng: np.random.Generator) -> tuple[Vec, Vec, Vec]:
    """Desired q, dq, ddq (rows x 7): per joint three sines of incommensurate frequency
    (0.1-0.45 Hz), so each joint reverses several times and the gravity load sweeps."""
    t = np.arange(round(duration * rate)) / rate
    q = np.tile(np.asarray(CENTRE_Q), (len(t), 1))
    dq = np.zeros_like(q)
    ddq = np.zeros_like(q)
    for j in range(N_JOINTS):
        f = rng.uniform(0.1, 0.45, 3)
        a = rng.dirichlet(np.ones(3)) * AMPLITUDE[j]
        phi = rng.uniform(0, 2 * np.pi, 3)
        for fi, ai, pi in zip(f, a, phi):
            w = 2 * np.pi * fi
            q[:, j] += ai * np.sin(w * t + pi)
            dq[:, j] += ai * w * np.cos(w * t + pi)
            ddq[:, j] -= ai * w * w * np.sin(w * t + pi)
    if np.any(q < np.asarray(Q_MIN) + 0.05) or np.any(q > np.asarray(Q_MAX) - 0.05):
        raise ConfigError("the excitation leaves the joint limits; check CENTRE_Q / AMPLITUDE")
    return q, dq, ddq


def simulate(model: mujoco.MjModel, reality: Reality, noise: SensorNoise, duration: float,
             rate: float, seed: int, physics: PhysicsConfig | None = None) -> TwinRun:
    """Run the plant `model` (the rigid arm with the twin's physics already in it)."""
    physics = physics or PhysicsConfig()
    rng = np.random.default_rng(seed)
    q_d, dq_d, ddq_d = excitation(duration, rate, rng)
    # The controller's feedforward comes from the *nominal* model, as on a real cell.
    feedforward = ArmDynamics().series(q_d, dq_d, ddq_d).full
    n, h = len(q_d), 1.0 / rate
    sub = round(h / physics.timestep)
    if abs(sub * physics.timestep - h) > 1e-12:
        raise ConfigError(f"control period {h} s is not a whole number of physics steps")
    model.opt.timestep = physics.timestep
    data = mujoco.MjData(model)
    idx = ArmIndex.from_model(model)
    data.qpos[idx.qpos], data.qvel[idx.dof] = q_d[0], dq_d[0]
    bias = rng.normal(0.0, noise.torque_bias_std, N_JOINTS) + reality.torque_bias
    ripple = rng.normal(0.0, noise.actuation_std, (n, N_JOINTS))
    kp, kd = np.asarray(KP), np.asarray(KD)
    delay_steps = round(reality.delay / physics.timestep)

    out_q, out_dq, out_tau, out_cmd = (np.empty((n, N_JOINTS)) for _ in range(4))
    applied = np.empty((n, N_JOINTS))
    saturated = 0
    if not np.array_equal(idx.torque_adr, 3 * np.arange(N_JOINTS) + 2) or not np.array_equal(
            idx.actuators, np.arange(N_JOINTS)):
        raise ConfigError("the twin expects the arm's 7 motors and 7 torque sensors in order")
    torque = data.sensordata[2::3]  # a view: the joint-axis component of each torque sensor
    ctrl = data.ctrl
    weights = np.ones(sub + 1)
    weights[[0, -1]] = 0.5  # trapezoid over the period's substep starts, both ends included
    weights /= sub
    lag = round(reality.sensor_lag / physics.timestep)
    if abs(lag * physics.timestep - reality.sensor_lag) > 1e-12:
        raise ConfigError(f"Reality.sensor_lag {reality.sensor_lag} s is not a whole number of "
                          f"{physics.timestep} s physics steps")
    history = np.zeros((n * sub + 1, N_JOINTS))  # the sensors at every substep's start
    mujoco.mj_forward(model, data)
    for k in range(n):
        q_m = quantise(data.qpos[idx.qpos] + reality.encoder_offset, noise.encoder_counts_per_rev)
        dq_m = data.qvel[idx.dof] + rng.normal(0.0, noise.velocity_std, N_JOINTS)
        cmd = feedforward[k] + kp * (q_d[k] - q_m) + kd * (dq_d[k] - dq_m)
        cmd, sat = saturate_torque(cmd)
        saturated += bool(np.any(sat))
        out_q[k], out_dq[k], out_cmd[k] = q_m, dq_m, cmd
        applied[k] = cmd + ripple[k]
        for s in range(sub):
            g = k * sub + s - delay_steps  # the substep whose command now reaches the joint
            new = applied[max(g // sub, 0)]
            old = applied[max((g - 1) // sub, 0)]
            ctrl[:] = new if g % sub else 0.5 * (old + new)  # a jump: centred on t_n
            mujoco.mj_step(model, data)  # sensors at the substep's start state and torque
            history[k * sub + s] = torque
            if s == 0:
                # the substep at t_k closes the previous period: now its mean is known
                end = k * sub - lag  # a lagging sensor's period ended `lag` substeps ago
                reading = (history[max(end, 0)] if end < sub
                           else weights @ history[end - sub:end + 1])
                out_tau[k] = ((1.0 + reality.torque_gain) * reading + bias
                              + rng.normal(0.0, noise.torque_std, N_JOINTS))
        if not np.all(np.isfinite(data.qpos)):
            raise ConfigError(f"the twin's simulation diverged at t = {k * h:.3f} s")
    return TwinRun(np.arange(n) * h, out_q, out_dq, out_tau, out_cmd, saturated, bias)
