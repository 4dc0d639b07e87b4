"""The arm-dynamics twin's effects that MuJoCo expresses in the arm's own spec: joint friction
(``frictionloss`` + ``damping``), a payload body, a link's mass and inertia, rotor inertia
(``armature``), a tilted base (the model's gravity turned). Sizes and joints per arm: twins/arm_twin_scale.py."""

from __future__ import annotations

import mujoco
import numpy as np

from serpar.sim.physics import PhysicsConfig
from serpar.sim.tilt import tilted_gravity
from serpar.twins.arm_twin_scale import ArmScale


def plant_model(spec: mujoco.MjSpec) -> mujoco.MjModel:
    PhysicsConfig(sleep=False).apply(spec)
    return spec.compile()


def friction(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator,
             scale: ArmScale) -> dict[str, float]:
    n = scale.n
    coulomb = mag * scale.coulomb * rng.uniform(0.7, 1.3, n)
    viscous = mag * scale.viscous * rng.uniform(0.7, 1.3, n)
    for j, name in enumerate(scale.arm.joint_names):
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


def payload(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator,
            scale: ArmScale) -> dict[str, float]:
    """A solid box of ``mag`` kg (times the arm's payload scale) fixed to the flange."""
    mass = mag * scale.payload_scale
    com = np.array([rng.uniform(-0.04, 0.04), rng.uniform(-0.04, 0.04), rng.uniform(0.02, 0.10)])
    half = np.array([0.03, 0.03, 0.03])
    fx, fy, fz = scale.arm.flange_pos
    body = spec.body(scale.arm.flange_body).add_body(
        name="payload", pos=[fx + com[0], fy + com[1], fz + com[2]])
    body.mass = mass
    body.inertia = mass / 3.0 * (half[[1, 0, 0]] ** 2 + half[[2, 2, 1]] ** 2)  # solid box
    body.explicitinertial = True
    # CoM at the body origin (unset = NaN)
    body.ipos, body.iquat = [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]
    return {"mass": mass, "com_x": float(com[0]), "com_y": float(com[1]), "com_z": float(com[2]),
            "Ixx": float(body.inertia[0]), "Iyy": float(body.inertia[1]),
            "Izz": float(body.inertia[2]), "Ixy": 0.0, "Ixz": 0.0, "Iyz": 0.0,
            # the extent the diagnosis fits: a box's second moment of mass is m diag(half^2 / 3)
            "Lxx": float(half[0] / np.sqrt(3.0)), "Lyy": float(half[1] / np.sqrt(3.0)),
            "Lzz": float(half[2] / np.sqrt(3.0)), "Lyx": 0.0, "Lzx": 0.0, "Lzy": 0.0}


def link_inertia(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator,
                 scale: ArmScale) -> dict[str, float]:
    link = int(rng.choice(scale.inertia_links))
    s = float(mag * rng.choice([-1.0, 1.0]))
    body = spec.body(scale.arm.link_bodies[link - 1])
    body.mass *= 1.0 + s
    if np.all(np.isfinite(body.fullinertia)):
        body.fullinertia = [v * (1.0 + s) for v in body.fullinertia]
    else:  # a file that gives principal moments (MJCF diaginertia)
        body.inertia = [v * (1.0 + s) for v in body.inertia]
    return {f"link{i}": (s if i == link else 0.0) for i in range(1, scale.n + 1)}


def armature(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator,
             scale: ArmScale) -> dict[str, float]:
    """Rotor inertia the model lacks on the arm's rotor joints: ``mag`` times the joint's rotor
    inertia of reference (the file's armature; twins/arm_twin_scale.py where it has none),
    scattered +-50 % per joint (a drive's rotor, reflected through its gear: the Panda's
    nominal 0.1 kg m^2 is the order of a Panda-class drive's)."""
    out = {}
    for j, name in enumerate(scale.arm.joint_names):
        joint = spec.joint(name)
        extra = (float(mag * scale.armature[j] * rng.uniform(0.5, 1.5))
                 if j + 1 in scale.rotor_joints else 0.0)
        joint.armature += extra
        out[f"Ia{j + 1}"] = extra
    return out


def base_tilt(spec: mujoco.MjSpec, mag: float, rng: np.random.Generator,
              scale: ArmScale) -> dict[str, float]:
    """The arm's base off level by ``mag`` rad, in a random direction: the plant's gravity
    turned as the diagnosis' base_tilt turns it (sim/tilt.py)."""
    azimuth = rng.uniform(0.0, 2 * np.pi)
    alpha, beta = mag * np.cos(azimuth), mag * np.sin(azimuth)
    spec.option.gravity = tilted_gravity(np.array(spec.option.gravity, float),
                                         np.array([alpha, beta]))[0]
    return {"alpha": float(alpha), "beta": float(beta)}
