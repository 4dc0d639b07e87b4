"""Changes to the simulated arm's physics that MuJoCo expresses exactly: what a diagnosis of the
real cell found missing from the nominal model (sim/plants/from_model_file.py builds them
from a diagnosis model file), applied where the arm is built (:func:`serpar.sim.scene.build_scene_spec`
via ``SceneConfig.arm_plant``), so every path that builds the cell sees the same plant.

Only the *plant* changes: the controllers keep their own nominal arm model
(``serpar.controllers.arm_model``), exactly as a real controller keeps libfranka's model when the
real arm differs from it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm import (
    ACTUATOR_NAMES,
    FLANGE_D,
    FLANGE_SITE,
    HAND_BODY,
    JOINT_NAMES,
    MDH_A,
    MDH_ALPHA,
    MDH_D,
    N_JOINTS,
    TORQUE_SENSOR_NAMES,
)
from serpar.sim.plants.drive_friction import DriveFrictionLaw

PAYLOAD_BODY = "plant_payload"
FLANGE_BODY = "link7"
MDH_PARAMS = ("alpha", "a", "theta", "d", "beta")
"""Order of one row of :attr:`ArmPlantChanges.mdh_errors` (serpar.kinematics.mdh's link model)."""
MAX_ANGLE_ERROR = 0.1  # [rad] beyond this an "error" is another robot, not a calibration
MAX_LENGTH_ERROR = 0.05  # [m]
MAX_REF = 0.2  # [rad] the diagnosis' own bound on an encoder offset
MAX_DELAY = 0.1  # [s]
MAX_ARMATURE = 1.0  # [kg m^2] a rotor inertia change ten times the Panda's reflected armature
INTERP_LINEAR = 1
"""MJCF ``interp="linear"`` of a sensor or actuator history (MuJoCo 4's Python bindings give no
enum)."""


def _floats(name: str, values: tuple[float, ...], lo: float, hi: float) -> None:
    if values and (len(values) != N_JOINTS
                   or not all(math.isfinite(v) and lo <= v <= hi for v in values)):
        raise ConfigError(f"{name} {values}: () or {N_JOINTS} finite values in {lo}..{hi}")


@dataclass(frozen=True)
class PayloadBody:
    """A rigid body fixed to the flange (the diagnosis' ``payload`` effect)."""

    mass: float
    """[kg] > 0."""
    com: tuple[float, float, float]
    """Centre of mass from the flange origin, in link-7 (flange) axes [m]."""
    inertia: tuple[float, float, float, float, float, float]
    """About the CoM, link-7 axes: Ixx, Iyy, Izz, Ixy, Ixz, Iyz [kg m^2]."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass) and 0 < self.mass <= 50):
            raise ConfigError(f"payload mass {self.mass} kg: valid 0 < mass <= 50")
        if len(self.com) != 3 or not all(math.isfinite(c) and abs(c) <= 1 for c in self.com):
            raise ConfigError(f"payload com {self.com}: 3 finite values within 1 m of the flange")
        if len(self.inertia) != 6 or not all(math.isfinite(v) for v in self.inertia):
            raise ConfigError(f"payload inertia {self.inertia}: 6 finite values "
                              "(Ixx, Iyy, Izz, Ixy, Ixz, Iyz)")
        why = inertia_problem(self.inertia)
        if why:
            raise ConfigError(f"payload inertia {self.inertia}: {why}")


EXTENT = ("Lxx", "Lyx", "Lyy", "Lzx", "Lzy", "Lzz")
"""A body's extent: the lower-triangular factor L of its mass's second moment about the CoM,
``integral (r - c)(r - c)^T dm = mass L L^T`` [m]."""


def inertia_from_extent(mass: float, extent: tuple[float, ...] | NDArray[np.float64]
                        ) -> tuple[float, float, float, float, float, float]:
    """(Ixx, Iyy, Izz, Ixy, Ixz, Iyz) about the CoM of a body of ``mass`` with ``extent``
    (:data:`EXTENT`). Any extent gives a physically consistent body: a positive semi-definite
    second moment is exactly that condition (eigenvalues >= 0 and the triangle inequalities of
    the principal moments; Wensing, Kim & Slotine 2017), so a fit in these parameters is
    admissible by construction. A negative mass gives the negative of such a body (mass a
    nominal model carries and the machine lacks)."""
    lxx, lyx, lyy, lzx, lzy, lzz = (float(v) for v in extent)
    low = np.array([[lxx, 0.0, 0.0], [lyx, lyy, 0.0], [lzx, lzy, lzz]])
    second = mass * low @ low.T
    i = np.trace(second) * np.eye(3) - second
    return (float(i[0, 0]), float(i[1, 1]), float(i[2, 2]), float(i[0, 1]), float(i[0, 2]),
            float(i[1, 2]))


def inertia_problem(inertia: tuple[float, ...]) -> str:
    """'' when (Ixx, Iyy, Izz, Ixy, Ixz, Iyz) is a rigid body's tensor about its CoM, else why
    not (MuJoCo refuses such a tensor at compile time)."""
    xx, yy, zz, xy, xz, yz = inertia
    w = np.linalg.eigvalsh(np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    if w[0] <= 0:
        return f"eigenvalues {w[0]:.3g}, {w[1]:.3g}, {w[2]:.3g} kg m^2 are not all positive"
    if w[0] + w[1] < w[2] * (1 - 1e-9):
        return f"principal moments {w[0]:.3g} + {w[1]:.3g} < {w[2]:.3g} kg m^2 (no mass has them)"
    return ""


@dataclass(frozen=True)
class ArmPlantChanges:
    """The arm's physics beyond the nominal MJCF. Empty tuples / None / 0 leave a part nominal."""

    frictionloss: tuple[float, ...] = ()
    """Dry friction per joint [N m] (MuJoCo ``frictionloss``); replaces the scene's
    ``arm_joint_friction``."""
    damping: tuple[float, ...] = ()
    """Viscous friction per joint [N m s/rad], the total (nominal included)."""
    drive: DriveFrictionLaw | None = None
    """Drive friction MuJoCo has no element for (sigmoid, Stribeck): the cell's runtime sets it
    as a torque before every substep (sim/plants/drive_friction.py)."""
    armature: tuple[float, ...] = ()
    """Rotor inertia added to each joint's nominal armature [kg m^2] (negative: less; the
    total is at least 0)."""
    joint_ref: tuple[float, ...] = ()
    """Encoder reading minus link angle per joint [rad] (MuJoCo joint ``ref``: the link stands
    in its MJCF frame when qpos = ref, so qpos reads the link angle plus the offset)."""
    link_mass_scale: tuple[float, ...] = ()
    """Relative error of links 1..7's mass and inertia (0.1 = 10 % heavier; CoM unchanged)."""
    payload: PayloadBody | None = None
    mdh_errors: tuple[tuple[float, ...], ...] = ()
    """Per joint 1..7: errors of (alpha, a, theta, d, beta) [rad, m], the model of
    :mod:`serpar.kinematics.mdh`. Row i moves body link<i>'s frame; beta_i tilts the next frame."""
    actuation_delay: float = 0.0
    """[s] Torque commands reach the arm's joints this late (MuJoCo actuator ``delay``)."""
    torque_sensor_delay: float = 0.0
    """[s] The joint torque sensors read this late (MuJoCo sensor ``delay``)."""
    source: str = ""
    """Where the changes come from (a model file), for messages."""
    not_applied: tuple[str, ...] = ()
    """One line per diagnosed effect (or parameter) the plant cannot express, with why."""

    def __post_init__(self) -> None:
        _floats("frictionloss", self.frictionloss, 0.0, 20.0)
        _floats("damping", self.damping, 0.0, 50.0)
        _floats("armature", self.armature, -MAX_ARMATURE, MAX_ARMATURE)
        if self.drive is not None and not isinstance(self.drive, DriveFrictionLaw):
            raise ConfigError(f"drive must be a DriveFrictionLaw, got {type(self.drive).__name__}")
        _floats("joint_ref", self.joint_ref, -MAX_REF, MAX_REF)
        _floats("link_mass_scale", self.link_mass_scale, -0.9, 10.0)
        if self.payload is not None and not isinstance(self.payload, PayloadBody):
            raise ConfigError(f"payload must be a PayloadBody, got {type(self.payload).__name__}")
        if self.mdh_errors:
            bad = len(self.mdh_errors) != N_JOINTS or any(len(r) != len(MDH_PARAMS)
                                                          for r in self.mdh_errors)
            limits = (MAX_ANGLE_ERROR, MAX_LENGTH_ERROR, MAX_ANGLE_ERROR, MAX_LENGTH_ERROR,
                      MAX_ANGLE_ERROR)
            if bad or not all(math.isfinite(v) and abs(v) <= lim for r in self.mdh_errors
                              for v, lim in zip(r, limits)):
                raise ConfigError(f"mdh_errors: () or {N_JOINTS} rows of ({', '.join(MDH_PARAMS)}) "
                                  f"within {MAX_ANGLE_ERROR} rad / {MAX_LENGTH_ERROR} m")
        for name in ("actuation_delay", "torque_sensor_delay"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 <= value <= MAX_DELAY):
                raise ConfigError(f"{name} {value} s: valid 0..{MAX_DELAY} s")


def _rot(axis: int, angle: float) -> NDArray[np.float64]:
    c, s = math.cos(angle), math.sin(angle)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    r = np.eye(3)
    r[i, i] = r[j, j] = c
    r[i, j], r[j, i] = -s, s
    return r


def _quat(r: NDArray[np.float64]) -> list[float]:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(r).ravel())
    return q.tolist()


def link_frame(i: int, err: tuple[tuple[float, ...], ...]) -> tuple[list[float], list[float]]:
    """Body link<i+1>'s pos and quat in its parent: beta_{i-1} RotX(alpha) TransX(a) RotZ(theta)
    TransZ(d), with each nominal MD-H value plus its error. Joint i's RotZ(q) commutes with
    TransZ(d), so d belongs in the body frame and the joint still turns about its z axis."""
    alpha, a, theta, d, _ = err[i] if err else (0.0,) * 5
    alpha, a, d = alpha + MDH_ALPHA[i], a + MDH_A[i], d + MDH_D[i]
    rx = _rot(0, alpha)
    pos = np.array([a, 0.0, 0.0]) + rx @ np.array([0.0, 0.0, d])
    rot = rx @ _rot(2, theta)
    if i > 0 and err:
        tilt = _rot(1, err[i - 1][4])
        pos, rot = tilt @ pos, tilt @ rot
    return pos.tolist(), _quat(rot)


def _local_rotation(obj: mujoco.MjsBody | mujoco.MjsSite) -> NDArray[np.float64]:
    """The rotation an MJCF body or site is given (quat or axis-angle, as panda.xml writes)."""
    kind = obj.alt.type
    q = np.zeros(4)
    if kind == mujoco.mjtOrientation.mjORIENTATION_QUAT:
        q[:] = np.asarray(obj.quat, float) / np.linalg.norm(obj.quat)
    elif kind == mujoco.mjtOrientation.mjORIENTATION_AXISANGLE:
        ax = np.asarray(obj.alt.axisangle, float)
        mujoco.mju_axisAngle2Quat(q, ax[:3] / np.linalg.norm(ax[:3]), float(ax[3]))
    else:
        raise ConfigError(f"{obj.name}: its MJCF orientation ({kind}) is not a quat or an "
                          "axis-angle; a beta7 error cannot be applied to it")
    r = np.zeros(9)
    mujoco.mju_quat2Mat(r, q)
    return r.reshape(3, 3)


def _tilt_flange(spec: mujoco.MjSpec, beta7: float) -> None:
    """beta7 turns what joint 7 carries beyond its axis: the flange site and the hand."""
    tilt = _rot(1, beta7)
    for obj in (spec.site(FLANGE_SITE), spec.body(HAND_BODY)):
        rot = tilt @ _local_rotation(obj)
        obj.pos = (tilt @ np.asarray(obj.pos, float)).tolist()
        obj.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
        obj.quat = _quat(rot)


def apply_arm_plant(spec: mujoco.MjSpec, changes: ArmPlantChanges, timestep: float) -> None:
    """Edit the arm's own spec (``serpar.sim.arm.build_arm_spec``, before it is attached)."""
    for j, name in enumerate(JOINT_NAMES):
        joint = spec.joint(name)
        if changes.frictionloss:
            joint.frictionloss = changes.frictionloss[j]
        if changes.damping:
            damping = np.array(joint.damping, float)  # MuJoCo 4: [linear, higher-order terms]
            damping[0] = changes.damping[j]
            joint.damping = damping
        if changes.joint_ref:
            joint.ref = changes.joint_ref[j]
        if changes.armature:
            joint.armature = max(joint.armature + changes.armature[j], 0.0)
    for j, scale in enumerate(changes.link_mass_scale):
        body = spec.body(f"link{j + 1}")
        body.mass *= 1.0 + scale
        # first moment and inertia scale with the mass: the CoM stays where the MJCF puts it
        body.fullinertia = [v * (1.0 + scale) for v in body.fullinertia]
    if changes.mdh_errors:
        for i in range(N_JOINTS):
            body = spec.body(f"link{i + 1}")
            body.pos, quat = link_frame(i, changes.mdh_errors)
            body.alt.type = mujoco.mjtOrientation.mjORIENTATION_QUAT
            body.quat = quat
        if changes.mdh_errors[-1][4]:
            _tilt_flange(spec, changes.mdh_errors[-1][4])
    if changes.payload is not None:
        p = changes.payload
        body = spec.body(FLANGE_BODY).add_body(name=PAYLOAD_BODY, pos=[0.0, 0.0, FLANGE_D])
        body.explicitinertial = True
        body.mass, body.ipos, body.fullinertia = p.mass, list(p.com), list(p.inertia)
    if changes.actuation_delay > 0:
        for name in ACTUATOR_NAMES:
            act = spec.actuator(name)
            act.delay = changes.actuation_delay
            # the history must reach back past the delay: one sample per physics step
            act.nsample = history_samples(changes.actuation_delay, timestep)
            # zero-order hold would apply a 1 kHz command from the first physics step at or
            # after tick + delay (0.5436 ms acts as 0.6 ms at a 0.1 ms step); read linearly, the
            # one step that straddles tick + delay carries the new command for exactly the
            # fraction of it after that instant, so every tick's impulse is a continuous delay's
            act.interp = INTERP_LINEAR
    if changes.torque_sensor_delay > 0:
        for name in TORQUE_SENSOR_NAMES:
            sensor = spec.sensor(name)
            sensor.delay = changes.torque_sensor_delay
            sensor.nsample = history_samples(changes.torque_sensor_delay, timestep)
            sensor.interp = INTERP_LINEAR  # a delay between two steps


def history_samples(delay: float, timestep: float) -> int:
    """MuJoCo history length for a ``delay`` at the physics step (one sample per step)."""
    return math.ceil(delay / timestep) + 2
