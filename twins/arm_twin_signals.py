"""The arm-dynamics twin's effects that act outside the arm's MjModel, in its sensors and
drives (sim/plants/arm_reality.py's :class:`Reality`): torque-sensor gain and offset, actuation
latency, torque-sensor timing, encoder offset and scale, Stribeck friction, the published
sigmoid friction, a torque ripple, a coupled wrist's motor. Sizes and joints per arm: twins/arm_twin_scale.py."""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.sim.arm import GAZ_FRICTION_PHI
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_reality import Coupling, Reality
from serpar.sim.plants.drive_friction import STRIBECK_SMOOTHING
from serpar.sim.plants.moving_arm import TwinRun
from serpar.sim.rigid_arm import ArmDynamics
from serpar.twins.arm_twin_physics import friction
from serpar.twins.arm_twin_scale import ArmScale

Vec = NDArray[np.float64]

STRIBECK_RATIO = (1.5, 2.5)
"""Static over Coulomb friction Fs / Fc of each drive (harmonic drives: ~1.5-2.5)."""
STRIBECK_SPEED = (0.02, 0.08)
"""Stribeck velocity vs of each drive [rad/s]: below it the friction rises to Fs."""
RIPPLE_PERIOD_DEG = (10.0, 45.0)
"""Period of the torque ripple in the joint angle [deg] (8-36 per revolution)."""
SIGMOID_SHIFT = 0.05
"""[rad/s] Largest |phi3| of the sigmoid twin (Gaz et al.'s Panda: 0.004-0.046)."""
COUPLED_SPREAD = (0.7, 1.3)
"""Per-parameter scatter of a coupled motor's Iam, fvm, fsm about the magnitude."""


def reality(effect: str, mag: float, rng: np.random.Generator, scale: ArmScale
            ) -> tuple[Reality, dict[str, float]]:
    """Sensor and timing effects: torque_sensor, latency, sensor_timing, encoder_offset."""
    n = scale.n
    if effect == "torque_sensor":
        gain = mag * rng.uniform(0.5, 1.0, n) * rng.choice([-1.0, 1.0])
        bias = rng.uniform(0.1, 0.5, n) * rng.choice([-1.0, 1.0], n) * scale.factor
        return (Reality(torque_gain=gain, torque_bias=bias, n=n),
                {f"gain{j + 1}": float(g) for j, g in enumerate(gain)})
    if effect == "latency":
        delay = round(mag, 4)
        return Reality(delay=delay, n=n), {"delay": delay}
    if effect == "sensor_timing":
        lag = round(mag, 4)  # whole 0.1 ms substeps
        return Reality(sensor_lag=lag, n=n), {"lag": lag}
    if effect == "encoder_offset":
        # the loaded joints only: the first joint's (about gravity) is invisible to dynamics
        joints = list(scale.loaded_joints)
        off = np.zeros(n)
        off[joints] = rng.uniform(-1.0, 1.0, len(joints))
        off[joints] *= mag / np.max(np.abs(off[joints]))
        return (Reality(encoder_offset=off, n=n),
                {f"offset{j + 1}": float(off[j]) for j in joints})
    return Reality(n=n), {}


def stribeck(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator, scale: ArmScale
             ) -> tuple[Reality, dict[str, object]]:
    # Coulomb + viscous as joint_friction (MuJoCo's); the Stribeck excess acts in the drive
    n = scale.n
    params: dict[str, object] = dict(friction(spec, mag, rng, scale))
    fc = np.array([params[f"Fc{j + 1}"] for j in range(n)], float)
    ratio = rng.uniform(*STRIBECK_RATIO, n)
    vs = rng.uniform(*STRIBECK_SPEED, n)
    excess = (ratio - 1.0) * fc
    params.update({f"Fs{j + 1}": float(ratio[j] * fc[j]) for j in range(n)})
    params.update({f"dFs{j + 1}": float(excess[j]) for j in range(n)})  # the diagnosis' names
    params.update({f"vs{j + 1}": float(vs[j]) for j in range(n)})
    width = None
    if not scale.arm.is_panda:
        # the explicit smoothed sign's slope excess / width, over one 0.1 ms step, must move a
        # light joint (an arm file without rotor inertia) by well under its own speed
        h = PhysicsConfig().timestep
        width = np.maximum(STRIBECK_SMOOTHING, 2.0 * h * excess / scale.plant.inertia_min)
    return (Reality(stribeck_excess=excess, stribeck_speed=vs, stribeck_width=width, n=n),
            params)


def sigmoid(mag: float, rng: np.random.Generator, scale: ArmScale
            ) -> tuple[Reality, dict[str, object]]:
    """Drive friction in the published Panda form (Gaz et al. 2019): per joint phi1 = twice the
    Coulomb level of reference times the magnitude (+-30 %), phi2 = the Panda's steepness along
    the chain (+-30 %), phi3 within +-SIGMOID_SHIFT. It replaces Coulomb + viscous friction:
    the plant has no frictionloss, the drive loses the sigmoid (sim/plants/arm_reality.py)."""
    n = scale.n
    phi1 = 2.0 * mag * scale.coulomb * rng.uniform(0.7, 1.3, n)
    phi2 = np.interp(np.linspace(0.0, 6.0, n), np.arange(7.0), GAZ_FRICTION_PHI[1]) * rng.uniform(
        0.7, 1.3, n)
    phi3 = rng.uniform(-SIGMOID_SHIFT, SIGMOID_SHIFT, n)
    h = PhysicsConfig().timestep  # explicit: its slope at rest, over one step, stays small
    phi2 = np.minimum(phi2, 0.5 * scale.plant.inertia_min / (h * np.maximum(phi1, 1e-12) / 4))
    params: dict[str, object] = {}
    for k, phi in enumerate((phi1, phi2, phi3)):
        params.update({f"phi{k + 1}_{j + 1}": float(phi[j]) for j in range(n)})
    return Reality(sigmoid_phi=np.stack([phi1, phi2, phi3]), n=n), params


def _beyond_coulomb_viscous(loss: Vec, dq: Vec) -> tuple[Vec, list[int]]:
    """Per joint, the RMS of a drive's friction ``loss`` (rows x n) less its least-squares fit
    of sign(dq) and dq (what the library's joint friction takes), and the 1-based joints
    within half of the largest such leftover, largest first: where a friction form the
    library lacks shows (every drive has it; a joint that moves mostly far above its
    transition speed shows little beyond a Coulomb level)."""
    left = np.zeros(loss.shape[1])
    for j in range(loss.shape[1]):
        basis = np.column_stack([np.sign(dq[:, j]), dq[:, j]])
        coef = np.linalg.lstsq(basis, loss[:, j], rcond=None)[0]
        left[j] = float(np.sqrt(np.mean((loss[:, j] - basis @ coef) ** 2)))
    return left, [int(i) + 1 for i in np.argsort(-left) if left[i] >= 0.5 * left.max()]


FRICTION_FORMS = {
    "sigmoid_friction": "a smooth friction, a level phi1 / 2 at speed about an offset, through "
                        "zero at rest over ~1 / phi2 rad/s",
    "stribeck_friction": "extra friction at low speed (|dq| below its vs), falling from Fs to Fc"}
"""The withheld friction forms whose signature :func:`friction_signature` gives, in words."""


def friction_signature(effect: str, reality: Reality, run: TwinRun, rate: float
                       ) -> dict[str, object]:
    """Where a withheld friction form (a key of FRICTION_FORMS, the reality's only drive
    torque) shows: the drives' channels and velocities of :func:`_beyond_coulomb_viscous`,
    over the true motion, of the torque the plant's drive itself applies
    (:meth:`Reality.drive_torque`)."""
    q = run.q_true
    dq = np.gradient(q, axis=0) * rate
    torque = reality.drive_torque()
    if torque is None:
        raise ValueError(f"{effect}: the twin's reality applies no drive torque, so no friction to locate")
    loss = -np.array([torque(q[k], dq[k]) for k in range(len(q))])
    left, seen = _beyond_coulomb_viscous(loss, dq)
    j = seen[0]
    words = (f"every drive loses {FRICTION_FORMS[effect]}: beyond a Coulomb + viscous friction "
             f"it leaves most on joint {j} ({left[j - 1]:.3f} N m RMS), in the command "
             "(tau_J_d - tau_J), not in the link-side sensor")
    return {"channels": [f"tau_J_d{i}" for i in seen], "variables": [f"dq{i}" for i in seen],
            "beyond_coulomb_viscous_rms": [float(v) for v in left], "words": words}


def ripple(mag: float, rng: np.random.Generator, scale: ArmScale
           ) -> tuple[Reality, dict[str, object], dict[str, object]]:
    joint = int(rng.choice(scale.loaded_joints))
    period_deg = float(rng.uniform(*RIPPLE_PERIOD_DEG))
    phase = float(rng.uniform(0.0, 2 * np.pi))
    amp = float(mag * scale.factor[joint])
    j = joint + 1
    params: dict[str, object] = {"joint": j, "amplitude": amp, "period_deg": period_deg,
                                 "period_rad": float(np.radians(period_deg)), "phase": phase}
    words = (f"joint {j}'s drive adds {amp:.2f} N m sin(2 pi q{j} / {period_deg:.1f} deg + "
             f"phase): the command tau_J_d{j} is off by a ripple periodic in q{j}; the "
             "link-side sensor and the other joints are not")
    signature: dict[str, object] = {"channels": [f"tau_J_d{j}"], "variables": [f"q{j}"],
                                    "period_deg": period_deg, "words": words}
    return (Reality(ripple=((joint, amp, np.radians(period_deg), phase),), n=scale.n),
            params, signature)


def encoder_scale(mag: float, rng: np.random.Generator, scale: ArmScale
                  ) -> tuple[Reality, dict[str, object]]:
    first = int(rng.choice(scale.scale_joints))
    s = np.zeros(scale.n)
    s[first] = mag * rng.choice([-1.0, 1.0])
    others = [j for j in scale.loaded_joints if j != first]
    if rng.random() < 0.5 and others:  # a second, smaller one on another loaded joint
        second = int(rng.choice(others))
        s[second] = mag * rng.uniform(-1.0, 1.0)
    return (Reality(encoder_scale=s, n=scale.n),
            {f"scale{j + 1}": float(s[j]) for j in scale.loaded_joints})


def scale_signature(reality: Reality, run: TwinRun, rate: float,
                    scale: ArmScale) -> dict[str, object]:
    """Where the scale error shows: the misread encoders' own channels (q_j, carried through
    the model to every torque), and the torque channels it moves by at least half the most,
    the nominal model at the true motion against the model at the read one (std about the
    mean: the diagnosis tares each sensor's constant). Gravity carries most of it, inertia
    the rest."""
    dyn = ArmDynamics(arm=scale.arm)
    q = run.q_true
    dq = np.gradient(q, axis=0) * rate  # the true motion is noise-free: plain differences
    ddq = np.gradient(dq, axis=0) * rate
    rows = slice(2, -2, 20)  # 50 Hz rows are plenty for the slow excitation
    gain = 1.0 + reality.encoder_scale
    true = dyn.link_torque(q[rows], dq[rows], ddq[rows])
    read = dyn.link_torque(reality.encoder_reading(q[rows]), gain * dq[rows], gain * ddq[rows])
    shift = np.std(true - read, axis=0)
    c = int(np.argmax(shift)) + 1
    # every joint within half of the largest: an angle's error moves several joints' gravity
    seen = [int(i) + 1 for i in np.argsort(-shift) if shift[i] >= 0.5 * shift[c - 1]]
    scaled = [int(i) for i in np.argsort(-np.abs(reality.encoder_scale))
              if reality.encoder_scale[i]]
    j = scaled[0] + 1
    return {"channels": [f"q{i + 1}" for i in scaled]
                        + [name for i in seen for name in (f"tau_J{i}", f"tau_J_d{i}")],
            "variables": [f"q{i + 1}" for i in scaled],
            "torque_shift_std": [float(v) for v in shift],
            "words": f"encoder {j} reads q{j} (1 {reality.encoder_scale[j - 1]:+.4f}) about its "
                     f"zero: the model's torque (gravity mostly) is off by an amount growing with "
                     f"q{j}, most on joint {c} ({shift[c - 1]:.2f} N m std), in both tau_J{c} "
                     f"and tau_J_d{c}"}


def coupled_pair(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator, scale: ArmScale
                 ) -> tuple[Reality, dict[str, float], list[list[int]]]:
    """The last two joints on a coupled wrist: the motor of joint n also turns joint n-1 (the
    TX40's joints 5 and 6), so it spins with q_n-1 + q_n: each of the two drives carries its
    rotor inertia and viscous friction in the other joint's motion (Reality.coupling) and its
    dry friction with the sign of their sum (a fixed tendon q_n-1 + q_n with that
    ``frictionloss``: MuJoCo's friction constraint, so the motor sticks as a joint does). The
    reality, the answer's Iam<n>, fvm<n>, fsm<n>, and the recording's ``couplings``
    ([[n-1, n]], 1-based)."""
    n = scale.n
    a, m = n - 2, n - 1
    iam, fvm, fsm = (float(mag * ref * rng.uniform(*COUPLED_SPREAD)) for ref in scale.coupled)
    tendon = spec.add_tendon(name="twin_coupled_motor", frictionloss=fsm)
    for name in (scale.arm.joint_names[a], scale.arm.joint_names[m]):
        tendon.wrap_joint(name, 1.0)
    # Coulomb's law as the joints' own dry friction has it (arm_twin_physics.friction)
    tendon.solref_friction = [2.0 * PhysicsConfig().timestep, 1.0]
    tendon.solimp_friction = [0.99, 0.999, 0.001, 0.5, 2.0]
    params = {f"Iam{n}": iam, f"fvm{n}": fvm, f"fsm{n}": fsm}
    return Reality(coupling=Coupling(a, m, iam, fvm), n=n), params, [[a + 1, m + 1]]
