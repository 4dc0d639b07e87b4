"""How the arm-dynamics twin drives an arm, whatever its joint count: where its excitation moves
(:attr:`ArmPlant.centre`, :attr:`ArmPlant.amplitude`), the tracking loop's gains, the drives'
torque limits, and the arm's MuJoCo spec with a motor and a link-side torque sensor per joint
(:func:`plant_spec`). The Panda keeps its own tuned values (bit for bit the twin it always
was); any other arm gets them from its joint limits and its inertia (:func:`arm_plant`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.sim.arm import TORQUE_LIMITS
from serpar.sim.rigid_arm import PANDA_ARM, ArmDynamics, ArmModel

Vec = NDArray[np.float64]

CENTRE_Q: tuple[float, ...] = (0.0, -0.4, 0.0, -2.0, 0.0, 1.8, 0.785398)
"""Centre of the Panda's excitation: an elbow-up pose with the big joints carrying gravity."""
AMPLITUDE: tuple[float, ...] = (0.7, 0.55, 0.6, 0.55, 0.9, 0.6, 1.0)
"""Peak excursion of each Panda joint's sum of sines [rad]; stays 0.1 rad inside every limit."""
KP: tuple[float, ...] = (600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0)
KD: tuple[float, ...] = (15.0, 50.0, 15.0, 20.0, 10.0, 10.0, 5.0)
"""PD gains of the Panda's tracking loop: libfranka's joint impedance example with less damping
on joints 1, 3 and the wrist, so that the loop keeps its phase margin under 5 ms of actuation
latency. When joint 2 nears zero, joints 1 and 3 turn about nearly one axis and their
difference mode has only the rotors' inertia (~0.1 kg m^2): the example's 50 N m s/rad then
puts its crossover near 500 rad/s, and a 3.8 ms latency made it ring at 30-60 Hz and
saturate at 87 N m."""
MAX_AMPLITUDE = 0.8
"""[rad] Another arm's excursion per joint (the Panda's are 0.55-1.0)."""
LIMIT_MARGIN = 0.15
"""[rad] Another arm's excitation stays this far inside each joint limit."""
OMEGA, ZETA = 24.0, 0.7
"""Another arm's loop per joint: natural frequency [rad/s] and damping ratio at its mean
inertia, the median of the Panda's gains at its own (17-43 rad/s, 0.26-1.08)."""
OMEGA_MAX = 60.0
"""[rad/s] Ceiling of the loop's natural frequency at the joint's *least* effective inertia
(1 / M^-1_jj over the excitation): where joints line up (the Panda's difference mode above) a
gain sized for the mean inertia rings under 5 ms of latency; at 60 rad/s (84 rad/s damping
crossover) 4.5 ms costs 0.38 rad of phase."""
PROBE_POSES = 200
"""Poses drawn in the excitation box at which an arm's inertia is measured (fixed seed)."""


@dataclass(frozen=True, eq=False)
class ArmPlant:
    """How the twin drives one arm (module docstring)."""

    arm: ArmModel
    centre: Vec
    amplitude: Vec
    kp: Vec
    kd: Vec
    torque_limit: Vec
    """[N m] per joint (inf: the file states none)."""
    inertia: Vec
    """Mean diagonal of the joint-space inertia (armature included) over the excitation box
    [kg m^2]: the joint's own torque scale for the effects' magnitudes."""
    inertia_min: Vec
    """Least effective inertia 1 / M^-1_jj over the box [kg m^2]."""
    coupling_gain: Vec
    """max |M^-1[j, i]| over the box, (n, n) [1/(kg m^2)]: how much joint j accelerates per N m
    on joint i (sizes an explicit torque on i that depends on j's acceleration)."""

    @property
    def n(self) -> int:
        return self.arm.n

    def probe_poses(self) -> Vec:
        """PROBE_POSES poses drawn uniformly in the excitation box (fixed seed)."""
        rng = np.random.default_rng(0)
        return self.centre + self.amplitude * rng.uniform(-1.0, 1.0, (PROBE_POSES, self.n))

    def saturate(self, tau: Vec) -> tuple[Vec, NDArray[np.bool_]]:
        """Clip to the drives' torque limits; returns (clipped torque, which joints saturated)."""
        lim = self.torque_limit
        return np.clip(tau, -lim, lim), np.abs(tau) > lim


def _box(arm: ArmModel) -> tuple[Vec, Vec]:
    """Another arm's excitation: about the middle of each joint's range (an unlimited or
    +-2 pi joint taken as +-pi: one turn shows every pose), MAX_AMPLITUDE or what the range
    leaves inside its margin."""
    lo = np.maximum(np.asarray(arm.q_min, float), -np.pi)
    hi = np.minimum(np.asarray(arm.q_max, float), np.pi)
    centre = 0.5 * (lo + hi)
    amplitude = np.minimum(MAX_AMPLITUDE, 0.5 * (hi - lo) - LIMIT_MARGIN)
    return centre, np.maximum(amplitude, 0.05)


def _torque_limits(arm: ArmModel, model: mujoco.MjModel) -> Vec:
    if arm.is_panda:
        return np.asarray(TORQUE_LIMITS, float)
    ids = [model.joint(name).id for name in arm.joint_names]
    rng = np.abs(np.asarray(model.jnt_actfrcrange[ids], float)).max(axis=1)
    limited = np.asarray(model.jnt_actfrclimited[ids], bool) & (rng > 0)
    return np.where(limited, rng, np.inf)


@lru_cache(maxsize=8)
def arm_plant(arm: ArmModel = PANDA_ARM) -> ArmPlant:
    """The twin's drive of ``arm`` (cached per arm object)."""
    dyn = ArmDynamics(arm=arm)
    if arm.is_panda:
        centre, amplitude = np.asarray(CENTRE_Q, float), np.asarray(AMPLITUDE, float)
    else:
        centre, amplitude = _box(arm)
    rng = np.random.default_rng(0)
    q = centre + amplitude * rng.uniform(-1.0, 1.0, (PROBE_POSES, arm.n))
    _, full = dyn.mass_link_and_full(q)
    inv = np.linalg.inv(full)
    inertia = np.einsum("kii->ki", full).mean(axis=0)
    inertia_min = (1.0 / np.einsum("kii->ki", inv)).min(axis=0)
    coupling_gain = np.abs(inv).max(axis=0)
    if arm.is_panda:
        kp, kd = np.asarray(KP, float), np.asarray(KD, float)
    else:
        # sized for the mean inertia, capped where the joint is lightest (OMEGA_MAX)
        kp = np.minimum(OMEGA**2 * inertia, OMEGA_MAX**2 * inertia_min)
        kd = np.minimum(2 * ZETA * OMEGA * inertia, 2 * ZETA * OMEGA_MAX * inertia_min)
    return ArmPlant(arm, centre, amplitude, kp, kd, _torque_limits(arm, dyn.model), inertia,
                    inertia_min, coupling_gain)


def motor_name(j: int) -> str:
    return f"twin_motor{j + 1}"


def sensor_name(j: int) -> str:
    return f"twin_tau_J{j + 1}"


def plant_spec(arm: ArmModel = PANDA_ARM) -> mujoco.MjSpec:
    """The arm's spec as the twin's plant: the Panda's own (its motors and torque sensors are in
    panda.xml); any other arm gets a motor per joint and a link-side torque sensor: a site on
    the joint's child body at the joint, its z along the joint axis (as panda.xml's tau_site),
    so the sensor's z is the torque the parent transmits about the axis (no armature, no joint
    friction: they act in the drive)."""
    spec = arm.make_spec()
    if arm.is_panda:
        return spec
    for j, name in enumerate(arm.joint_names):
        joint = spec.joint(name)
        body = spec.body(arm.link_bodies[j])
        site = body.add_site(name=f"twin_tau_site{j + 1}", pos=list(joint.pos))
        site.alt.type = mujoco.mjtOrientation.mjORIENTATION_ZAXIS
        site.alt.zaxis = list(joint.axis)
        motor = spec.add_actuator(name=motor_name(j), target=name,
                                  trntype=mujoco.mjtTrn.mjTRN_JOINT)
        motor.set_to_motor()
        spec.add_sensor(name=sensor_name(j), type=mujoco.mjtSensor.mjSENS_TORQUE,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site.name)
    return spec
