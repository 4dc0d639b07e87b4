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
| link_friction | multiple of a real Panda's friction, as joint_friction | the same Coulomb + viscous friction, acting between the torque sensor and the link (bearings, seals): the sensor reads it, in tau_J as in tau_J_d |
| stribeck_friction | multiple of a real Panda's friction, as joint_friction | joint_friction's Coulomb + viscous, plus a Stribeck excess (Fs - Fc) exp(-(v/vs)^2) against the motion: Fs/Fc 1.5-2.5, vs 0.02-0.08 rad/s per joint |
| torque_ripple | amplitude A [N m] of A sin(2 pi q_j / P + phi) in one drive | the joint (2-6), the period P (10-45 deg), the phase |
| encoder_scale | largest relative scale error abs(s) (encoder reads q (1 + s) about its zero, dq too) | its joint (2-4), the sign; half the time a second, smaller one on another joint of 2-6 |

The torque ripple (:data:`OUT_OF_LIBRARY`) has no candidate in the diagnosis library: it should
come out as a structured residual that no library effect explains, characterised as an
empirical term. Stribeck friction and encoder scale have candidates; the blind bench also
draws them with their candidate withheld (:data:`WITHHELD`), as physics outside the library.
The answers of these three carry a ``signature``: the channels the residual shows in, the
variables it follows, in words.
"""

from __future__ import annotations

from collections.abc import Mapping

import mujoco
import numpy as np
import pyarrow as pa

from serpar.errors import ConfigError
from serpar.sim import channels as ch
from serpar.sim.arm import JOINT_NAMES, N_JOINTS, PANDA_COULOMB_FRICTION
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.moving_panda import Reality, SensorNoise, TwinRun, simulate
from serpar.sim.recording import PhaseSegment, Recording, RecordingMeta
from serpar.sim.rigid_arm import FLANGE_BODY, FLANGE_Z, ArmDynamics, rigid_arm_spec

OUT_OF_LIBRARY: tuple[str, ...] = ("torque_ripple",)
"""Effects the diagnosis has no candidate for: they must come out as unexplained residual."""
WITHHELD: tuple[str, ...] = ("stribeck_friction", "encoder_scale")
"""Library effects the blind bench also draws with their candidate withheld from the
diagnosis: physics outside the library, with a signature to score the empirical term by."""
PARTLY_IN_LIBRARY: dict[str, tuple[str, ...]] = {
    "stribeck_friction": ("joint_friction",),
    "encoder_scale": ("encoder_offset",),
}
"""Library effects that express part of an effect's physics (not a wrong finding when
established with it, or for it while its candidate is withheld): Stribeck friction's Coulomb
and viscous levels; a scale error's mean over the joint's travel, a constant offset."""
EFFECTS: tuple[str, ...] = ("joint_friction", "link_friction", "payload", "link_inertia",
                            "torque_sensor", "latency", "sensor_timing", "encoder_offset",
                            "stribeck_friction", "encoder_scale", "armature", *OUT_OF_LIBRARY)
MAGNITUDE_RANGE: dict[str, tuple[float, float]] = {
    "joint_friction": (0.2, 1.0),
    "link_friction": (0.2, 1.0),
    "payload": (0.2, 1.5),
    "link_inertia": (0.1, 0.3),
    "torque_sensor": (0.02, 0.06),
    "latency": (0.001, 0.004),
    "sensor_timing": (0.0005, 0.002),
    "encoder_offset": (0.001, 0.004),
    "stribeck_friction": (0.5, 1.0),
    "torque_ripple": (0.15, 0.6),
    "encoder_scale": (0.005, 0.015),
    "armature": (0.3, 1.0),
}
PANDA_VISCOUS: tuple[float, ...] = (0.2, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1)
"""Viscous joint friction of a Panda-class drive at scale 1 [N m s/rad] (order of Gaz et al.)."""
STRIBECK_RATIO = (1.5, 2.5)
"""Static over Coulomb friction Fs / Fc of each drive (harmonic drives: ~1.5-2.5)."""
STRIBECK_SPEED = (0.02, 0.08)
"""Stribeck velocity vs of each drive [rad/s]: below it the friction rises to Fs."""
RIPPLE_PERIOD_DEG = (10.0, 45.0)
"""Period of the torque ripple in the joint angle [deg] (8-36 per revolution)."""
LOADED_JOINTS = (1, 2, 3, 4, 5)
"""Joints 2-6 (0-based): the ones whose angle moves a gravity load or whose drive ripples."""
SCALE_JOINTS = (1, 2, 3)
"""Joints 2-4 (0-based), one of which has encoder_scale's largest error: their gravity load
shows a scale error (20 s, s = 0.005: 2.3-8 x the noise before any fit); on joints 5-6 even
s = 0.01 reads 1.35 x (joint 5) or is taken up by an offset to 1.25 x (joint 6)."""
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
            "Ixy": 0.0, "Ixz": 0.0, "Iyz": 0.0,
            # the extent the diagnosis fits: a box's second moment of mass is m diag(half^2 / 3)
            "Lxx": float(half[0] / np.sqrt(3.0)), "Lyy": float(half[1] / np.sqrt(3.0)),
            "Lzz": float(half[2] / np.sqrt(3.0)), "Lyx": 0.0, "Lzx": 0.0, "Lzy": 0.0}


def _link_inertia(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator) -> dict[str, float]:
    link = int(rng.choice(INERTIA_LINKS))
    scale = float(mag * rng.choice([-1.0, 1.0]))
    body = spec.body(f"link{link}")
    body.mass *= 1.0 + scale
    body.fullinertia = [v * (1.0 + scale) for v in body.fullinertia]
    return {f"link{i}": (scale if i == link else 0.0) for i in range(1, N_JOINTS + 1)}


ROTOR_JOINTS = (3, 4, 5, 6, 7)
"""Joints an armature twin adds rotor inertia to: joint 1's and 2's are grouped with the links'
inertias (the diagnosis computes it: diagnosis/arm_dynamics_grouping.py), so no data could
name them; a twin that hid them would hide link inertia under another name."""


def _armature(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator) -> dict[str, float]:
    """Rotor inertia the model lacks on :data:`ROTOR_JOINTS`: ``mag`` times the model's own
    armature, scattered +-50 % per joint (a drive's rotor, reflected through its gear: the
    nominal 0.1 kg m^2 is the order of a Panda-class drive's)."""
    out = {}
    for j, name in enumerate(JOINT_NAMES):
        joint = spec.joint(name)
        extra = float(mag * joint.armature * rng.uniform(0.5, 1.5)) if j + 1 in ROTOR_JOINTS else 0.0
        joint.armature += extra
        out[f"Ia{j + 1}"] = extra
    return out


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


def _stribeck(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator
              ) -> tuple[Reality, dict[str, object], dict[str, object]]:
    # Coulomb + viscous as joint_friction (MuJoCo's); the Stribeck excess acts in the drive
    params: dict[str, object] = dict(_friction(spec, mag, rng))
    fc = np.array([params[f"Fc{j + 1}"] for j in range(N_JOINTS)], float)
    ratio = rng.uniform(*STRIBECK_RATIO, N_JOINTS)
    vs = rng.uniform(*STRIBECK_SPEED, N_JOINTS)
    excess = (ratio - 1.0) * fc
    params.update({f"Fs{j + 1}": float(ratio[j] * fc[j]) for j in range(N_JOINTS)})
    params.update({f"vs{j + 1}": float(vs[j]) for j in range(N_JOINTS)})
    order = np.argsort(-excess)
    j = int(order[0]) + 1
    words = (f"every drive loses extra torque at low speed (|dq| below its vs, 0.02-0.08 rad/s), "
             f"joint {j} most ({excess[j - 1]:.2f} N m more below {vs[j - 1]:.3f} rad/s): "
             "friction falling from Fs to Fc with speed, beyond Coulomb + viscous; in the "
             "command (tau_J_d - tau_J), not in the link-side sensor")
    signature: dict[str, object] = {"channels": [f"tau_J_d{i + 1}" for i in order],
                                    "variables": [f"dq{j}"], "words": words}
    return Reality(stribeck_excess=excess, stribeck_speed=vs), params, signature


def _ripple(mag: float, rng: np.random.Generator
            ) -> tuple[Reality, dict[str, object], dict[str, object]]:
    joint = int(rng.choice(LOADED_JOINTS))
    period_deg = float(rng.uniform(*RIPPLE_PERIOD_DEG))
    phase = float(rng.uniform(0.0, 2 * np.pi))
    j = joint + 1
    params: dict[str, object] = {"joint": j, "amplitude": mag, "period_deg": period_deg,
                                 "period_rad": float(np.radians(period_deg)), "phase": phase}
    words = (f"joint {j}'s drive adds {mag:.2f} N m sin(2 pi q{j} / {period_deg:.1f} deg + "
             f"phase): the command tau_J_d{j} is off by a ripple periodic in q{j}; the "
             "link-side sensor and the other joints are not")
    signature: dict[str, object] = {"channels": [f"tau_J_d{j}"], "variables": [f"q{j}"],
                                    "period_deg": period_deg, "words": words}
    return Reality(ripple=((joint, mag, np.radians(period_deg), phase),)), params, signature


def _encoder_scale(mag: float, rng: np.random.Generator) -> tuple[Reality, dict[str, object]]:
    first = int(rng.choice(SCALE_JOINTS))
    scale = np.zeros(N_JOINTS)
    scale[first] = mag * rng.choice([-1.0, 1.0])
    if rng.random() < 0.5:  # a second, smaller one anywhere in 2-6
        second = int(rng.choice([j for j in LOADED_JOINTS if j != first]))
        scale[second] = mag * rng.uniform(-1.0, 1.0)
    return Reality(encoder_scale=scale), {f"scale{j + 1}": float(scale[j]) for j in LOADED_JOINTS}


def _scale_signature(reality: Reality, run: TwinRun) -> dict[str, object]:
    """Where the scale error shows: the channel whose link torque it moves most, the nominal
    model at the true motion against the model at the read one (std about the mean: the
    diagnosis tares each sensor's constant). Gravity carries most of it, inertia the rest."""
    dyn = ArmDynamics()
    q = run.q_true
    dq = np.gradient(q, axis=0) * RATE  # the true motion is noise-free: plain differences
    ddq = np.gradient(dq, axis=0) * RATE
    rows = slice(2, -2, 20)  # 50 Hz rows are plenty for the slow excitation
    gain = 1.0 + reality.encoder_scale
    true = dyn.link_torque(q[rows], dq[rows], ddq[rows])
    read = dyn.link_torque(reality.encoder_reading(q[rows]), gain * dq[rows], gain * ddq[rows])
    shift = np.std(true - read, axis=0)
    c = int(np.argmax(shift)) + 1
    # every joint within half of the largest: an angle's error moves several joints' gravity
    seen = [int(i) + 1 for i in np.argsort(-shift) if shift[i] >= 0.5 * shift[c - 1]]
    scaled = [int(i) for i in np.argsort(-np.abs(reality.encoder_scale)) if reality.encoder_scale[i]]
    j = scaled[0] + 1
    return {"channels": [name for i in seen for name in (f"tau_J{i}", f"tau_J_d{i}")],
            "variables": [f"q{i + 1}" for i in scaled],
            "torque_shift_std": [float(v) for v in shift],
            "words": f"encoder {j} reads q{j} (1 {reality.encoder_scale[j - 1]:+.4f}) about its "
                     f"zero: the model's torque (gravity mostly) is off by an amount growing with "
                     f"q{j}, most on joint {c} ({shift[c - 1]:.2f} N m std), in both tau_J{c} "
                     f"and tau_J_d{c}"}


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
    params: Mapping[str, object] = {}
    reality = Reality()
    signature: dict[str, object] | None = None
    if effect == "joint_friction":
        params = _friction(spec, magnitude, effect_rng)
    elif effect == "link_friction":
        params = _friction(spec, magnitude, effect_rng)
        viscous = np.array([params[f"Fv{j + 1}"] for j in range(N_JOINTS)])
        reality = Reality(link_side_friction=True, link_side_viscous=viscous)
    elif effect == "stribeck_friction":
        reality, params, signature = _stribeck(spec, magnitude, effect_rng)
    elif effect == "torque_ripple":
        reality, params, signature = _ripple(magnitude, effect_rng)
    elif effect == "encoder_scale":
        reality, params = _encoder_scale(magnitude, effect_rng)
    elif effect == "payload":
        params = _payload(spec, magnitude, effect_rng)
    elif effect == "link_inertia":
        params = _link_inertia(spec, magnitude, effect_rng)
    elif effect == "armature":
        params = _armature(spec, magnitude, effect_rng)
    elif effect is not None:
        reality, params = _reality(effect, magnitude, effect_rng)
    run = simulate(_plant(spec), reality, noise, duration, RATE,
                   int(sim_seed.integers(2**31)))
    if effect == "encoder_scale":
        signature = _scale_signature(reality, run)
    answer: dict[str, object] = {"effect": effect, "magnitude": magnitude, "params": params,
                                 "torque_offset": [float(b) for b in run.torque_offset],
                                 "saturated_samples": run.saturated}
    if signature is not None:
        answer["signature"] = signature
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
