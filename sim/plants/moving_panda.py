"""The "real" arm of the arm-dynamics twin: MuJoCo forward dynamics of a rigid-hand Panda with
whatever physics the twin adds, driven at 1 kHz by a joint-space tracking controller, read by
sensors with a realistic noise model.

Timing, as the diagnosis assumes it (diagnosis/arm_dynamics_signals.py):
- row k is the control period starting at t_k = k / rate;
- ``q``, ``dq`` are read at t_k (encoder quantisation, velocity noise);
- ``tau_J`` is the link-side torque sensor's mean over the period that ends at t_k (a strain
  gauge behind an integrating ADC; trapezoidal over the 0.1 ms physics substeps);
- ``tau_J_d`` is the command computed from the row's measurements and held over the period;
  the drive delivers it, ``delay`` later, with a white torque ripple per period, plus what
  the reality's drive adds between motor and link-side sensor (Stribeck friction, a
  position-periodic ripple: ``qfrc_applied`` at every substep, which the sensor reads only
  through the motion it causes, like MuJoCo's joint friction).

MuJoCo's semi-implicit Euler step is a leapfrog: the force of substep n acts as an impulse
centred on t_n, so a torque switched at the start of substep n would act half a substep
(0.05 ms) early. The substep on which the applied torque jumps therefore gets the mean of the
old and the new torque: that puts the jump at t_n, to second order (without it a diagnosis
of an effect-free twin finds a latency of -0.05 ms, 3 sigma on 20 s).
"""

from __future__ import annotations

from collections.abc import Callable
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
STRIBECK_SMOOTHING = 1e-3
"""[rad/s] Width of the smoothed sign of the Stribeck friction (tanh(v / width))."""


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
    encoder_scale: Vec = field(default_factory=lambda: np.zeros(N_JOINTS))
    """Relative scale error of each encoder about its zero: it reads q (1 + s) + offset."""
    delay: float = 0.0
    """Actuation latency: a command reaches the joint this much later [s]."""
    sensor_lag: float = 0.0
    """The torque sensors' readings belong to this much earlier than the encoders' [s]
    (a whole number of physics substeps)."""
    stribeck_excess: Vec = field(default_factory=lambda: np.zeros(N_JOINTS))
    """Static minus Coulomb friction of each drive, Fs - Fc [N m]: at joint speed v the drive
    loses (Fs - Fc) exp(-(v / vs)^2) more, against the motion (the Coulomb and viscous parts
    are the plant's MuJoCo frictionloss and damping)."""
    stribeck_speed: Vec = field(default_factory=lambda: np.full(N_JOINTS, 0.05))
    """Stribeck velocity vs of each drive [rad/s]."""
    ripple: tuple[tuple[int, float, float, float], ...] = ()
    """Position-periodic transmission ripple, one (joint index 0-6, amplitude [N m], period
    [rad], phase [rad]) per rippling joint: the drive adds A sin(2 pi q / period + phase)."""
    link_side_friction: bool = False
    """The joints' dry friction (MuJoCo's frictionloss) acts between the torque sensor and the
    link (output bearings, seals), so the sensors read it: the drive must pass it through."""
    link_side_viscous: Vec = field(default_factory=lambda: np.zeros(N_JOINTS))
    """The part of each joint's damping [N m s/rad] that acts on the link side of the sensor."""

    def __post_init__(self) -> None:
        for name, lo, hi in (("torque_gain", -np.inf, np.inf), ("torque_bias", -np.inf, np.inf),
                             ("encoder_offset", -np.inf, np.inf), ("encoder_scale", -0.05, 0.05),
                             ("stribeck_excess", 0.0, 5.0), ("stribeck_speed", 1e-3, 1.0),
                             ("link_side_viscous", 0.0, 5.0)):
            v = np.asarray(getattr(self, name), float)
            if v.shape != (N_JOINTS,) or not np.all(np.isfinite(v)):
                raise ConfigError(f"Reality.{name} needs {N_JOINTS} finite values")
            if np.any(v < lo) or np.any(v > hi):
                raise ConfigError(f"Reality.{name}={v.tolist()} outside {lo:g}..{hi:g}")
            object.__setattr__(self, name, v)
        if not 0.0 <= self.delay <= 0.02:
            raise ConfigError(f"Reality.delay={self.delay} s outside 0..0.02 s")
        if not 0.0 <= self.sensor_lag <= 0.005:
            raise ConfigError(f"Reality.sensor_lag={self.sensor_lag} s outside 0..0.005 s")
        object.__setattr__(self, "ripple", tuple(_ripple_entry(r) for r in self.ripple))
        joints = [r[0] for r in self.ripple]
        if len(set(joints)) != len(joints):
            raise ConfigError(f"Reality.ripple names a joint twice: {joints}")

    def encoder_reading(self, q: Vec) -> Vec:
        """What the encoders read at the true angles q, before quantisation [rad]."""
        return q * (1.0 + self.encoder_scale) + self.encoder_offset

    def drive_torque(self) -> Callable[[Vec, Vec], Vec] | None:
        """The drive's torque beyond its command at true (q, dq) [N m], or None without one
        (the simulation then skips it): Stribeck friction and position ripple."""
        stribeck = bool(np.any(self.stribeck_excess > 0))
        if not stribeck and not self.ripple:
            return None
        neg_excess, inv_speed = -self.stribeck_excess, 1.0 / self.stribeck_speed
        inv_width = 1.0 / STRIBECK_SMOOTHING
        joint = np.array([r[0] for r in self.ripple], int)
        amp, period, phase = (np.array([r[i] for r in self.ripple], float) for i in (1, 2, 3))
        wavenumber = 2 * np.pi / period if len(period) else period

        def torque(q: Vec, dq: Vec) -> Vec:
            # called at every 0.1 ms substep: a few whole-vector ufuncs (~2.5 us), no loops.
            # tanh instead of sign: continuous through v = 0, where MuJoCo's frictionloss
            # constraint holds the joint; 1 mm/s keeps h * slope / inertia < 1 at the twin's
            # Fs - Fc (<= 0.8 N m on wrist joints of >= 0.1 kg m^2): explicit and still stable
            if stribeck:
                x = dq * inv_speed
                out = neg_excess * np.exp(-x * x) * np.tanh(dq * inv_width)
            else:
                out = np.zeros(N_JOINTS)
            if len(joint):
                out[joint] += amp * np.sin(wavenumber * q[joint] + phase)
            return out

        return torque


def _ripple_entry(r: tuple[int, float, float, float]) -> tuple[int, float, float, float]:
    try:
        values = np.asarray(r, float)
    except (TypeError, ValueError):
        values = np.empty(0)
    if values.shape != (4,) or not np.all(np.isfinite(values)):
        raise ConfigError(f"Reality.ripple entry {r} needs 4 finite values "
                          "(joint index, amplitude, period, phase)")
    j, amp, period, phase = r
    if int(j) != j or not 0 <= j < N_JOINTS:
        raise ConfigError(f"Reality.ripple joint index {j} outside 0..{N_JOINTS - 1}")
    if not 0.0 <= amp <= 5.0:
        raise ConfigError(f"Reality.ripple amplitude {amp} N m outside 0..5 N m")
    if not 0.01 <= period <= 2 * np.pi:
        raise ConfigError(f"Reality.ripple period {period} rad outside 0.01..2 pi rad")
    return int(j), float(amp), float(period), float(phase)


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
    q_true: Vec
    """The true joint angles at the rows' times (what the encoders read, before their errors
    and quantisation) [rad]: for the answer and the tests, never for the recording."""


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
    # start where the encoders read the desired pose through their scale (1 for s = 0)
    data.qpos[idx.qpos] = q_d[0] / (1.0 + reality.encoder_scale)
    data.qvel[idx.dof] = dq_d[0] / (1.0 + reality.encoder_scale)
    bias = rng.normal(0.0, noise.torque_bias_std, N_JOINTS) + reality.torque_bias
    drive_noise = rng.normal(0.0, noise.actuation_std, (n, N_JOINTS))
    drive_torque = reality.drive_torque()  # None: no extra drive physics, no per-substep cost
    link_side = reality.link_side_friction or bool(np.any(reality.link_side_viscous))
    friction_row = mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF
    kp, kd = np.asarray(KP), np.asarray(KD)
    delay_steps = round(reality.delay / physics.timestep)

    out_q, out_dq, out_tau, out_cmd, out_true = (np.empty((n, N_JOINTS)) for _ in range(5))
    applied = np.empty((n, N_JOINTS))
    saturated = 0
    first = np.arange(N_JOINTS)
    if not (np.array_equal(idx.torque_adr, 3 * first + 2) and np.array_equal(idx.actuators, first)
            and np.array_equal(idx.qpos, first) and np.array_equal(idx.dof, first)):
        raise ConfigError("the twin expects the arm's 7 joints, motors and torque sensors first, "
                          "in order")
    # views: the drive's extra torque is read and written at every substep without copies
    q_true, dq_true, extra = (x[:N_JOINTS] for x in (data.qpos, data.qvel, data.qfrc_applied))
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
        out_true[k] = data.qpos[idx.qpos]
        q_m = quantise(reality.encoder_reading(out_true[k]), noise.encoder_counts_per_rev)
        # the velocity is the encoder's, differentiated: it carries the same scale error
        dq_m = (data.qvel[idx.dof] * (1.0 + reality.encoder_scale)
                + rng.normal(0.0, noise.velocity_std, N_JOINTS))
        cmd = feedforward[k] + kp * (q_d[k] - q_m) + kd * (dq_d[k] - dq_m)
        cmd, sat = saturate_torque(cmd)
        saturated += bool(np.any(sat))
        out_q[k], out_dq[k], out_cmd[k] = q_m, dq_m, cmd
        applied[k] = cmd + drive_noise[k]
        for s in range(sub):
            g = k * sub + s - delay_steps  # the substep whose command now reaches the joint
            new = applied[max(g // sub, 0)]
            old = applied[max((g - 1) // sub, 0)]
            ctrl[:] = new if g % sub else 0.5 * (old + new)  # a jump: centred on t_n
            if drive_torque is not None:  # acts in the drive, before the link-side sensor
                extra[:] = drive_torque(q_true, dq_true)
            if link_side:  # the link-side damping at the substep's start, as the sensors see it
                viscous = reality.link_side_viscous * dq_true
            mujoco.mj_step(model, data)  # sensors at the substep's start state and torque
            history[k * sub + s] = torque
            if link_side:
                # MuJoCo's sensor reads the torque that moves the link (motor + friction); a
                # sensor before the link-side friction reads what the drive passes through
                history[k * sub + s] += viscous
                if reality.link_side_friction:
                    rows = data.efc_type[:data.nefc] == friction_row
                    np.subtract.at(history[k * sub + s], data.efc_id[:data.nefc][rows],
                                   data.efc_force[:data.nefc][rows])
            if s == 0:
                # the substep at t_k closes the previous period: now its mean is known
                end = k * sub - lag  # a lagging sensor's period ended `lag` substeps ago
                reading = (history[max(end, 0)] if end < sub
                           else weights @ history[end - sub:end + 1])
                out_tau[k] = ((1.0 + reality.torque_gain) * reading + bias
                              + rng.normal(0.0, noise.torque_std, N_JOINTS))
        if not np.all(np.isfinite(data.qpos)):
            raise ConfigError(f"the twin's simulation diverged at t = {k * h:.3f} s")
    return TwinRun(np.arange(n) * h, out_q, out_dq, out_tau, out_cmd, saturated, bias, out_true)
