"""Arm-dynamics twins: a "real" Panda with one concealed piece of physics the nominal model
lacks, recorded like a libfranka log (q, dq, tau_J, tau_J_d at 1 kHz), for
``serpar twin`` / ``serpar blind-bench`` and the tests of the time-series diagnosis.

The reality is built from MuJoCo's own physics wherever MuJoCo can express the effect
(``frictionloss`` + ``damping`` for joint friction, an added body for a payload, scaled body
inertias for a link error); sensor and drive effects (torque-sensor gain and bias, encoder
offset, actuation latency, torque-sensor timing) act on the signals in sim/plants/moving_panda.py. The answer
goes into the returned dict, never into the recording.

Magnitude per effect (drawn from the range in :data:`MAGNITUDE_RANGE` when not given):

| effect | magnitude | what else is drawn |
|---|---|---|
| joint_friction | multiple of a real Panda's friction (Gaz et al. 2019 Coulomb levels, viscous ~0.1-0.2 N m s/rad) | per-joint spread ±30 %; dry friction sticks at reversals |
| payload | mass [kg] | CoM: x, y within ±4 cm of the flange axis, z 2-10 cm out; a solid box |
| link_inertia | relative mass error of one link (inertia tensor scaled with it) | which link (3, 4 or 5), the sign |
| torque_sensor | largest gain error (0.03 = +3 %) | per-joint gains 50-100 % of it, one sign for all (a payload fit mimics it on tau_J), offsets ±0.1-0.5 N m |
| latency | actuation delay [s] | — (0.1 ms resolution) |
| sensor_timing | how late the torque sensors read against the encoders [s] | — (0.1 ms resolution; the simulated cell's own sensors read half a substep late, ~0.05 ms) |
| encoder_offset | largest offset [rad] | offsets of joints 2-6 (joint 1's is invisible to dynamics: gravity is along its axis) |
"""

from __future__ import annotations

import mujoco
import numpy as np
import pyarrow as pa

from serpar.errors import ConfigError
from serpar.sim import channels as ch
from serpar.sim.arm import JOINT_NAMES, N_JOINTS, PANDA_COULOMB_FRICTION
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.moving_panda import Reality, SensorNoise, TwinRun, simulate
from serpar.sim.recording import PhaseSegment, Recording, RecordingMeta
from serpar.sim.rigid_arm import FLANGE_BODY, FLANGE_Z, rigid_arm_spec

EFFECTS: tuple[str, ...] = ("joint_friction", "payload", "link_inertia", "torque_sensor",
                            "latency", "sensor_timing", "encoder_offset")
MAGNITUDE_RANGE: dict[str, tuple[float, float]] = {
    "joint_friction": (0.2, 1.0),
    "payload": (0.2, 1.5),
    "link_inertia": (0.1, 0.3),
    "torque_sensor": (0.02, 0.06),
    "latency": (0.001, 0.004),
    "sensor_timing": (0.0005, 0.002),
    "encoder_offset": (0.001, 0.004),
}
PANDA_VISCOUS: tuple[float, ...] = (0.2, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1)
"""Viscous joint friction of a Panda-class drive at scale 1 [N m s/rad] (order of Gaz et al.)."""
INERTIA_LINKS = (3, 4, 5)
"""Links a link_inertia twin may get wrong: the heavy ones (links 1-2 hardly load the joints)."""
DURATION = 20.0
RATE = 1000.0


def _plant(spec: mujoco.MjSpec) -> mujoco.MjModel:
    PhysicsConfig(sleep=False).apply(spec)
    return spec.compile()


def _friction(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator) -> dict[str, float]:
    coulomb = mag * np.asarray(PANDA_COULOMB_FRICTION) * rng.uniform(0.7, 1.3, N_JOINTS)
    viscous = mag * np.asarray(PANDA_VISCOUS) * rng.uniform(0.7, 1.3, N_JOINTS)
    for j, name in enumerate(JOINT_NAMES):
        joint = spec.joint(name)
        joint.frictionloss = float(coulomb[j])
        # dry friction as Coulomb's law: the stiffest stable friction constraint slides at
        # Fc from 1e-4 rad/s on and sticks below. MuJoCo's default soft one creeps through
        # 0.003-0.03 rad/s with a force that even lags against the motion.
        joint.solref_friction = [2.0 * PhysicsConfig().timestep, 1.0]
        joint.solimp_friction = [0.99, 0.999, 0.001, 0.5, 2.0]
        damping = np.array(joint.damping, float)  # MuJoCo 4: [linear, higher-order terms]
        damping[0] += viscous[j]  # on top of the nominal damping
        joint.damping = damping
    return {**{f"Fc{j + 1}": float(c) for j, c in enumerate(coulomb)},
            **{f"Fv{j + 1}": float(v) for j, v in enumerate(viscous)}}


def _payload(spec: mujoco.MjSpec, mass: float, rng: np.random.Generator) -> dict[str, float]:
    com = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.04, 0.04), rng.uniform(0.02, 0.10)])
    half = np.array([0.03, 0.03, 0.03])
    body = spec.body(FLANGE_BODY).add_body(name="payload", pos=[com[0], com[1], FLANGE_Z + com[2]])
    body.mass = mass
    body.inertia = mass / 3.0 * (half[[1, 0, 0]] ** 2 + half[[2, 2, 1]] ** 2)  # solid box
    body.explicitinertial = True
    body.ipos, body.iquat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]  # CoM at the body origin (unset = NaN)
    return {"mass": mass, "com_x": float(com[0]), "com_y": float(com[1]), "com_z": float(com[2]),
            "Ixx": float(body.inertia[0]), "Iyy": float(body.inertia[1]), "Izz": float(body.inertia[2]),
            "Ixy": 0.0, "Ixz": 0.0, "Iyz": 0.0}


def _link_inertia(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator) -> dict[str, float]:
    link = int(rng.choice(INERTIA_LINKS))
    scale = float(mag * rng.choice([-1.0, 1.0]))
    body = spec.body(f"link{link}")
    body.mass *= 1.0 + scale
    body.fullinertia = [v * (1.0 + scale) for v in body.fullinertia]
    return {f"link{i}": (scale if i == link else 0.0) for i in range(1, N_JOINTS + 1)}


def _reality(effect: str, mag: float, rng: np.random.Generator) -> tuple[Reality, dict[str, float]]:
    if effect == "torque_sensor":
        gain = mag * rng.uniform(0.5, 1.0, N_JOINTS) * rng.choice([-1.0, 1.0])
        bias = rng.uniform(0.1, 0.5, N_JOINTS) * rng.choice([-1.0, 1.0], N_JOINTS)
        return Reality(torque_gain=gain, torque_bias=bias), {f"gain{j + 1}": float(g) for j, g in enumerate(gain)}
    if effect == "latency":
        delay = round(mag, 4)
        return Reality(delay=delay), {"delay": delay}
    if effect == "sensor_timing":
        lag = round(mag, 4)  # whole 0.1 ms substeps
        return Reality(sensor_lag=lag), {"lag": lag}
    if effect == "encoder_offset":
        off = np.zeros(N_JOINTS)
        off[1:6] = rng.uniform(-1.0, 1.0, 5)
        off[1:6] *= mag / np.max(np.abs(off[1:6]))
        return Reality(encoder_offset=off), {f"offset{j + 1}": float(off[j]) for j in range(1, 6)}
    return Reality(), {}


def make_twin(effect: str | None, magnitude: float | None, seed: int,
              duration: float = DURATION, noise: SensorNoise | None = None
              ) -> tuple[Recording, dict[str, object]]:
    """A recording of a "real" arm with `effect` (None: the nominal arm), and the answer."""
    noise = noise or SensorNoise()
    if effect is not None and effect not in EFFECTS:
        raise ConfigError(f"unknown effect {effect!r}; valid: {', '.join(EFFECTS)} (or none)")
    if not 5.0 <= duration <= 120.0:
        raise ConfigError(f"duration {duration} s outside 5..120 s")
    effect_rng, sim_seed = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    if effect is not None and magnitude is None:
        magnitude = float(effect_rng.uniform(*MAGNITUDE_RANGE[effect]))
    if magnitude is not None and not (np.isfinite(magnitude) and magnitude > 0):
        raise ConfigError(f"magnitude {magnitude} must be a positive number")
    spec = rigid_arm_spec()
    params: dict[str, float] = {}
    reality = Reality()
    if effect == "joint_friction":
        params = _friction(spec, magnitude, effect_rng)
    elif effect == "payload":
        params = _payload(spec, magnitude, effect_rng)
    elif effect == "link_inertia":
        params = _link_inertia(spec, magnitude, effect_rng)
    elif effect is not None:
        reality, params = _reality(effect, magnitude, effect_rng)
    run = simulate(_plant(spec), reality, noise, duration, RATE,
                   int(sim_seed.integers(2**31)))
    answer = {"effect": effect, "magnitude": magnitude, "params": params,
              "torque_offset": [float(b) for b in run.torque_offset],
              "saturated_samples": run.saturated}
    return _recording(run, noise), answer


def _recording(run: TwinRun, noise: SensorNoise) -> Recording:
    cols = {ch.TIME: run.time}
    sigma = {}
    for names, x, std in ((ch.Q, run.q, noise.encoder_sigma), (ch.DQ, run.dq, noise.velocity_std),
                          (ch.TAU_J, run.tau_J, noise.torque_std),
                          (ch.TAU_J_D, run.tau_J_d, noise.actuation_std)):
        cols.update({c: x[:, j] for j, c in enumerate(names)})
        sigma.update({c: std for c in names})
    meta = RecordingMeta(
        source="sim", sample_rate_hz=RATE, channels=tuple(cols), noise_sigma=sigma,
        phases=(PhaseSegment("excitation", 0.0, float(run.time[-1])),),
        model={"arm": "assets/arm/panda.xml, hand rigid and closed",
               "controller": "joint PD (libfranka example gains) + nominal feedforward, 1 kHz",
               "notes": {"q": "encoder reading at the row's time",
                         "tau_J": "link-side torque, mean over the control period ending at the row's time",
                         "tau_J_d": "command held over the period starting at the row's time; "
                                    "noise_sigma = the drive's torque ripple about it"}})
    return Recording(meta, pa.table(cols))
