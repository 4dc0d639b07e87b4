"""The candidate effects of the arm-dynamics diagnosis for one arm and one recording: which
effects the recording's channels can show, over the arm's own joints, and which joints' encoder
errors its dynamics can see (computed from the model at the recording's states, no joint list
of any one arm).

Every effect is a change *relative to the arm's own model file* (its masses, inertias,
armature, damping), so a parameter of zero is "the file is right". What each channel shows
(docs/diagnosis.md, "Which torque the recording holds"):

* ``tau_J`` (link-side torque sensors, after the gearbox): payload, link inertia, encoder
  errors, the sensor's gain and timing, friction on the link side (bearings, seals);
* ``tau_J_d`` (the commanded torque): the same less the sensor's own errors, plus everything
  inside the drive (friction, rotor inertia, a coupled wrist's motor) and actuation latency;
* ``tau_drive`` (the drive torque from motor currents): what the command shows, less the
  latency; its gain and offset are the torque "sensor" gain and tare.

Friction and rotor inertia are named as drive effects when only a drive channel exists: with
no link-side sensor, friction on either side of the gearbox moves the same channel alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_sigmoid import sigmoid_effect
from serpar.diagnosis.arm_dynamics_signals import MAX_LATENCY_S
from serpar.diagnosis.arm_dynamics_tilt import tilt_effect
from serpar.diagnosis.family import Effect
from serpar.sim.plants.arm_changes import EXTENT

Vec = NDArray[np.float64]

OFFSET_BOUND = 0.2
"""[rad] Largest encoder offset searched: a mis-set zero, not a wrong joint."""
SCALE_BOUND = 0.05
"""Largest relative encoder scale error: a wrong gear ratio or resolution setting."""
VISIBLE_SHARE = 0.01
"""A joint's encoder offset (scale) is a candidate when its angle moves the gravity load (its
angle, rate and acceleration move the torques) by at least this share of the most sensitive
joint's, at the recording's states: below it the dynamics cannot see the error (a joint whose
axis is vertical carries no gravity change, a last joint turning a near-axial hand almost none)."""
ARMATURE_MAX = 5.0
"""[kg m^2] Largest rotor inertia searched, reflected to the joint (a 30 kg-class industrial
arm's base axis: ~0.4)."""
STICK_VELOCITY = 0.01
"""[rad/s] Below this a joint with dry friction may be stuck, and its Coulomb force is then
anywhere in [-Fc, Fc] (whatever balances the drive): rows weigh such samples as an interval,
not a value. Above it the twin's MuJoCo frictionloss is >= 99 % of Fc, and the encoder
velocity (central difference, noise ~1e-3 rad/s) has a certain sign. The default of
``ArmDynamicsConfig.stick_velocity``; a recording whose joints creep under force control sets
its own (diagnosis/episode_family.py)."""
STRIBECK_SPEEDS = np.geomspace(STICK_VELOCITY, 0.4, 20)
"""[rad/s] Grid of the Stribeck regressor; the search range of each joint's Stribeck speed (a
fall below the speed at which a joint may be stuck could not be seen)."""
PAYLOAD_PARAMS = ("mass", "com_x", "com_y", "com_z") + EXTENT
EXTENT_DIAGONAL = np.array([n[1] == n[2] for n in EXTENT])
EXTENT_START = np.where(EXTENT_DIAGONAL, 0.03, 0.0)
"""[m] A small body's extent: the search starts off L = 0, where the inertia's slope is 0.
Flange axes; CoM from the flange origin; inertia tensor about the CoM. The x0 mass is not
zero: at zero mass the CoM has no gradient to start from."""

COMMAND_ONLY = ("latency",)
"""Effects only a commanded torque shows (a command delivered late)."""
DRIVE_ONLY = ("joint_friction", "sigmoid_friction", "stribeck_friction", "armature",
              "coupled_pair")
"""Effects only a drive channel shows (inside the drive, before any link-side sensor)."""
LINK_ONLY = ("link_friction", "sensor_timing")
"""Effects that need the link-side sensors: friction after the gearbox is told from the
drive's only by a channel on that side; a sensor lag behind the encoders needs the sensor."""


@dataclass(frozen=True)
class Channels:
    """Which torques a recording holds."""

    link: bool
    """tau_J, the link-side torque sensors."""
    drive: str | None
    """``command`` (tau_J_d), ``measured`` (tau_drive) or None."""


@dataclass(frozen=True)
class Coupling:
    """One motor that turns two joints (a coupled wrist): the motor of joint ``motor`` also
    turns joint ``joint``, so it spins with their sum and its torque reaches both. Beyond each
    joint's own rotor inertia and friction (Ia, Fv of its own motion), each joint's drive takes
    the motor's inertia and viscous friction in the *other* joint's motion and its Coulomb
    friction with the sign of the sum (the published TX40 structure, FIGAROH's
    ``_add_coupling``: Iam6, fvm6, fsm6 on joints 5 and 6). 1-based joints."""

    joint: int
    motor: int


def tare(n: int, prefix: str = "tare") -> Effect:
    """The always-fitted torque offsets of n measured channels."""
    names = tuple(f"{prefix}{j}" for j in range(1, n + 1))
    return Effect("torque_tare", "torque sensor offsets (tares)", names, ("N m",) * n,
                  np.zeros(n), np.full(n, -20.0), np.full(n, 20.0))


def _friction(name: str, summary: str, n: int, bounds: tuple[float, float]) -> Effect:
    names = tuple(f"Fc{j}" for j in range(1, n + 1)) + tuple(f"Fv{j}" for j in range(1, n + 1))
    return Effect(name, summary, names, ("N m",) * n + ("N m s/rad",) * n, np.zeros(2 * n),
                  np.zeros(2 * n), np.r_[np.full(n, bounds[0]), np.full(n, bounds[1])],
                  physical_lower=True)


def arm_effects(n: int, channels: Channels, offset_joints: tuple[int, ...],
                scale_joints: tuple[int, ...], armature: Vec,
                couplings: tuple[Coupling, ...] = (),
                friction_bounds: tuple[float, float] = (10.0, 5.0)) -> tuple[Effect, ...]:
    """The candidates for an arm of ``n`` joints whose recording holds ``channels``.
    ``armature``: the model file's rotor inertias (a change may remove at most them);
    ``friction_bounds``: the arm's largest Coulomb [N m] and viscous [N m s/rad] friction
    (:attr:`serpar.sim.rigid_arm.ArmModel.friction_bounds`)."""
    J = range(1, n + 1)
    fc_max = friction_bounds[0]
    out: list[Effect] = []
    drive = channels.drive is not None
    if drive:
        out.append(_friction("joint_friction", "joint friction (Coulomb + viscous, inside the "
                             "drive)", n, friction_bounds))
    if drive:
        out.append(sigmoid_effect(n, fc_max))
    if channels.link:
        out.append(_friction("link_friction", "joint friction on the link side of the torque "
                             "sensors (Coulomb + viscous; bearings, seals: in the measured "
                             "torque as in the command)", n, friction_bounds))
    if drive:
        out.append(Effect(
            "stribeck_friction", "Stribeck friction (static friction above the Coulomb level, "
            "falling off with speed: dFs exp(-(v/vs)^2) per joint, dFs = Fs - Fc, vs its own "
            "transition speed)",
            tuple(f"dFs{j}" for j in J) + tuple(f"vs{j}" for j in J),
            ("N m",) * n + ("rad/s",) * n,
            np.r_[np.zeros(n), np.full(n, 0.05)], np.r_[np.zeros(n), np.full(n, STRIBECK_SPEEDS[0])],
            np.r_[np.full(n, fc_max), np.full(n, STRIBECK_SPEEDS[-1])],
            physical_lower=(True,) * n + (False,) * n,
            amplitude_of=(-1,) * n + tuple(range(n))))
        out.append(Effect(
            "armature", "rotor inertia (armature) per joint, inside the drive",
            tuple(f"Ia{j}" for j in J), ("kg m^2",) * n, np.zeros(n), -np.asarray(armature, float),
            np.full(n, ARMATURE_MAX), physical_lower=True))
        for c in couplings:
            m = c.motor
            out.append(Effect(
                "coupled_pair" if len(couplings) == 1 else f"coupled_pair{c.joint}{m}",
                f"motor {m} also turns joint {c.joint} (coupled drive): its rotor inertia and "
                f"friction load both joints' drives with the other's motion, its dry friction "
                f"with the sign of their sum",
                (f"Iam{m}", f"fvm{m}", f"fsm{m}"), ("kg m^2", "N m s/rad", "N m"),
                np.zeros(3), np.zeros(3),
                np.array([ARMATURE_MAX, friction_bounds[1], friction_bounds[0]]),
                physical_lower=True))
    out.append(Effect(
        "payload", "unmodelled payload at the flange (mass, centre of mass, extent: the "
        "Cholesky factor of its second moment of mass, so its inertia is physical; or the last "
        "link's own mass and inertia off by as much: the same torques)",
        PAYLOAD_PARAMS, ("kg", "m", "m", "m") + ("m",) * 6,
        np.r_[0.1, 0.0, 0.0, 0.05, EXTENT_START],
        np.r_[-3.0, -0.3, -0.3, -0.3, np.where(EXTENT_DIAGONAL, 0.0, -0.3)],
        np.r_[5.0, 0.3, 0.3, 0.5, np.full(6, 0.3)],
        physical_lower=(False,) * 4 + tuple(bool(d) for d in EXTENT_DIAGONAL),
        excess_words="the nominal model carries {value} at the flange that the arm does not have"))
    out.append(tilt_effect())
    out.append(Effect("link_inertia", "link mass/inertia error (relative, per link)",
                      tuple(f"link{j}" for j in J), ("1",) * n, np.zeros(n), np.full(n, -0.9),
                      np.full(n, 2.0)))
    if channels.link or channels.drive == "measured":
        out.append(Effect("torque_sensor", "torque sensor gain error (relative, per joint)",
                          tuple(f"gain{j}" for j in J), ("1",) * n, np.zeros(n),
                          np.full(n, -0.5), np.full(n, 0.5)))
    if channels.drive == "command":
        # a command cannot act before it is sent: 0 is a physical limit, and a fit that would
        # go below it says "no latency here", not an admissible finding
        out.append(Effect("latency", "actuation latency (command reaches the joint late)",
                          ("delay",), ("s",), np.zeros(1), np.zeros(1), np.array([MAX_LATENCY_S]),
                          physical_lower=True))
    if channels.link:
        out.append(Effect("sensor_timing", "torque sensors sampled out of step with the "
                          "encoders (lag)", ("lag",), ("s",), np.zeros(1), np.array([-0.005]),
                          np.array([0.005])))
    k = len(offset_joints)
    if k:
        out.append(Effect("encoder_offset", "joint encoder offsets (measured minus true angle)",
                          tuple(f"offset{j}" for j in offset_joints), ("rad",) * k, np.zeros(k),
                          np.full(k, -OFFSET_BOUND), np.full(k, OFFSET_BOUND)))
    k = len(scale_joints)
    if k:
        out.append(Effect("encoder_scale", "joint encoder scale errors (measured = true angle "
                          "x (1 + s))", tuple(f"scale{j}" for j in scale_joints), ("1",) * k,
                          np.zeros(k), np.full(k, -SCALE_BOUND), np.full(k, SCALE_BOUND)))
    return tuple(out)


def visible_joints(sensitivity: Vec) -> tuple[int, ...]:
    """1-based joints whose sensitivity (one value per joint, >= 0) is at least
    :data:`VISIBLE_SHARE` of the largest."""
    top = float(np.max(sensitivity)) if len(sensitivity) else 0.0
    if top <= 0:
        return ()
    return tuple(int(j) + 1 for j in np.flatnonzero(sensitivity >= VISIBLE_SHARE * top))
