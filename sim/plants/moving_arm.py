"""The "real" arm of the arm-dynamics twin: MuJoCo forward dynamics of an arm (the rigid-hand
Panda or any :class:`~serpar.sim.rigid_arm.ArmModel`) with whatever physics the twin adds,
driven at 1 kHz by a joint-space tracking controller (sim/plants/arm_plant.py), read by sensors
with a realistic noise model (sim/plants/arm_reality.py).

Timing, as the diagnosis assumes it (diagnosis/arm_dynamics_signals.py):
- row k is the control period starting at t_k = k / rate;
- ``q``, ``dq`` are read at t_k (encoder quantisation, velocity noise);
- ``tau_J`` is the link-side torque sensor's mean over the period that ends at t_k (a strain
  gauge behind an integrating ADC; trapezoidal over the 0.1 ms physics substeps);
- ``tau_J_d`` is the command computed from the row's measurements and held over the period;
  the drive delivers it, ``delay`` later, with a white torque ripple per period, plus what
  the reality's drive adds between motor and link-side sensor (Stribeck friction, a
  position-periodic ripple, a coupled motor: ``qfrc_applied`` at every substep, which the
  sensor reads only through the motion it causes, like MuJoCo's joint friction).

MuJoCo's semi-implicit Euler step is a leapfrog: the force of substep n acts as an impulse
centred on t_n, so a torque switched at the start of substep n would act half a substep
(0.05 ms) early. The substep on which the applied torque jumps therefore gets the mean of the
old and the new torque: that puts the jump at t_n, to second order (without it a diagnosis
of an effect-free twin finds a latency of -0.05 ms, 3 sigma on 20 s).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm_drive import ArmIndex, quantise
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_plant import ArmPlant, arm_plant, motor_name, sensor_name
from serpar.sim.plants.arm_reality import Reality, SensorNoise
from serpar.sim.rigid_arm import PANDA_ARM, ArmDynamics, ArmModel

Vec = NDArray[np.float64]


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


def excitation(duration: float, rate: float, rng: np.random.Generator,
               plant: ArmPlant | None = None) -> tuple[Vec, Vec, Vec]:
    """Desired q, dq, ddq (rows x n): per joint three sines of incommensurate frequency
    (0.1-0.45 Hz) about the plant's centre, within its amplitude, so each joint reverses
    several times and the gravity load sweeps."""
    plant = plant or arm_plant(PANDA_ARM)
    t = np.arange(round(duration * rate)) / rate
    q = np.tile(plant.centre, (len(t), 1))
    dq = np.zeros_like(q)
    ddq = np.zeros_like(q)
    for j in range(plant.n):
        f = rng.uniform(0.1, 0.45, 3)
        a = rng.dirichlet(np.ones(3)) * plant.amplitude[j]
        phi = rng.uniform(0, 2 * np.pi, 3)
        for fi, ai, pi in zip(f, a, phi):
            w = 2 * np.pi * fi
            q[:, j] += ai * np.sin(w * t + pi)
            dq[:, j] += ai * w * np.cos(w * t + pi)
            ddq[:, j] -= ai * w * w * np.sin(w * t + pi)
    arm = plant.arm
    if np.any(q < np.asarray(arm.q_min) + 0.05) or np.any(q > np.asarray(arm.q_max) - 0.05):
        raise ConfigError(f"the excitation leaves {arm.name}'s joint limits; check "
                          "sim/plants/arm_plant.py's centre and amplitude")
    return q, dq, ddq


def _check_layout(model: mujoco.MjModel, arm: ArmModel) -> None:
    """The loop addresses the arm's joints, motors and torque sensors as the first n of each."""
    n, first = arm.n, np.arange(arm.n)
    if arm.is_panda:
        idx = ArmIndex.from_model(model)
        qpos, dof, act, adr = idx.qpos, idx.dof, idx.actuators, idx.torque_adr
    else:
        joints = [model.joint(name) for name in arm.joint_names]
        qpos = np.array([j.qposadr[0] for j in joints])
        dof = np.array([j.dofadr[0] for j in joints])
        act = np.array([model.actuator(motor_name(j)).id for j in range(n)])
        adr = np.array([model.sensor_adr[model.sensor(sensor_name(j)).id] + 2 for j in range(n)])
    if not (np.array_equal(adr, 3 * first + 2) and np.array_equal(act, first)
            and np.array_equal(qpos, first) and np.array_equal(dof, first)
            and model.nu == n and model.nsensordata == 3 * n):
        raise ConfigError(f"the twin expects {arm.name}'s {n} joints, motors and torque sensors "
                          "first, in order, and nothing else actuated or sensed")


def simulate(model: mujoco.MjModel, reality: Reality, noise: SensorNoise, duration: float,
             rate: float, seed: int, physics: PhysicsConfig | None = None,
             arm: ArmModel = PANDA_ARM) -> TwinRun:
    """Run the plant `model` (the arm's plant spec, sim/plants/arm_plant.py, with the twin's
    physics already in it)."""
    physics = physics or PhysicsConfig()
    plant = arm_plant(arm)
    n_j = arm.n
    if reality.n != n_j:
        raise ConfigError(f"Reality is for {reality.n} joints, {arm.name} has {n_j}")
    rng = np.random.default_rng(seed)
    q_d, dq_d, ddq_d = excitation(duration, rate, rng, plant)
    # The controller's feedforward comes from the *nominal* model, as on a real cell.
    feedforward = ArmDynamics(arm=arm).series(q_d, dq_d, ddq_d).full
    n, h = len(q_d), 1.0 / rate
    sub = round(h / physics.timestep)
    if abs(sub * physics.timestep - h) > 1e-12:
        raise ConfigError(f"control period {h} s is not a whole number of physics steps")
    model.opt.timestep = physics.timestep
    data = mujoco.MjData(model)
    _check_layout(model, arm)
    # start where the encoders read the desired pose through their scale (1 for s = 0)
    data.qpos[:n_j] = q_d[0] / (1.0 + reality.encoder_scale)
    data.qvel[:n_j] = dq_d[0] / (1.0 + reality.encoder_scale)
    bias = rng.normal(0.0, noise.torque_bias_std, n_j) + reality.torque_bias
    drive_noise = rng.normal(0.0, noise.actuation_std, (n, n_j))
    drive_torque = reality.drive_torque()  # None: no extra drive physics, no per-substep cost
    link_side = reality.link_side_friction or bool(np.any(reality.link_side_viscous))
    friction_row = mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF
    kp, kd = plant.kp, plant.kd
    delay_steps = round(reality.delay / physics.timestep)

    out_q, out_dq, out_tau, out_cmd, out_true = (np.empty((n, n_j)) for _ in range(5))
    applied = np.empty((n, n_j))
    saturated = 0
    # views: the drive's extra torque is read and written at every substep without copies
    q_true, dq_true, ddq_last, extra = (x[:n_j] for x in (data.qpos, data.qvel, data.qacc,
                                                          data.qfrc_applied))
    torque = data.sensordata[2::3]  # a view: the joint-axis component of each torque sensor
    ctrl = data.ctrl
    weights = np.ones(sub + 1)
    weights[[0, -1]] = 0.5  # trapezoid over the period's substep starts, both ends included
    weights /= sub
    lag = round(reality.sensor_lag / physics.timestep)
    if abs(lag * physics.timestep - reality.sensor_lag) > 1e-12:
        raise ConfigError(f"Reality.sensor_lag {reality.sensor_lag} s is not a whole number of "
                          f"{physics.timestep} s physics steps")
    history = np.zeros((n * sub + 1, n_j))  # the sensors at every substep's start
    mujoco.mj_forward(model, data)
    for k in range(n):
        out_true[k] = q_true
        q_m = quantise(reality.encoder_reading(out_true[k]), noise.encoder_counts_per_rev)
        # the velocity is the encoder's, differentiated: it carries the same scale error
        dq_m = (dq_true * (1.0 + reality.encoder_scale)
                + rng.normal(0.0, noise.velocity_std, n_j))
        cmd = feedforward[k] + kp * (q_d[k] - q_m) + kd * (dq_d[k] - dq_m)
        cmd, sat = plant.saturate(cmd)
        saturated += bool(np.any(sat))
        out_q[k], out_dq[k], out_cmd[k] = q_m, dq_m, cmd
        applied[k] = cmd + drive_noise[k]
        for s in range(sub):
            g = k * sub + s - delay_steps  # the substep whose command now reaches the joint
            new = applied[max(g // sub, 0)]
            old = applied[max((g - 1) // sub, 0)]
            ctrl[:] = new if g % sub else 0.5 * (old + new)  # a jump: centred on t_n
            if drive_torque is not None:  # acts in the drive, before the link-side sensor
                extra[:] = drive_torque(q_true, dq_true, ddq_last)
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
                              + rng.normal(0.0, noise.torque_std, n_j))
        if not np.all(np.isfinite(data.qpos)):
            raise ConfigError(f"the twin's simulation diverged at t = {k * h:.3f} s")
    return TwinRun(np.arange(n) * h, out_q, out_dq, out_tau, out_cmd, saturated, bias, out_true)
