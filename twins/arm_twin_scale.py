"""How big the arm-dynamics twin's effects are on a given arm, and which joints and links they
touch (:class:`ArmScale`). The twin's magnitudes were drawn for the Panda; on another arm an
absolute one is scaled to that arm, and the Panda's joint lists are computed from its model.
The Panda gets its own constants (its twins are the same, bit for bit, as before any arm).

The rules (each value at magnitude 1; the twin multiplies by its drawn magnitude):

* torque scale ``s`` = RMS over joints and poses of the arm's gravity torque / the Panda's, at
  poses drawn in each arm's excitation box (sim/plants/arm_plant.py): a drive is sized for the
  load it lifts, and so are its friction and its ripple.
* per joint ``factor_j = min(s, inertia_j / PANDA_LIGHTEST)``: a joint lighter than the Panda's
  lightest (its wrist, 0.107 kg m^2 with its rotor) gets its torques scaled down with its
  inertia, so that a torque drawn for the Panda decelerates it no more than it would a Panda
  joint (the tracking loop, the excitation and the explicit Stribeck term were sized for that;
  an arm file without rotor inertias has wrists of 1e-3 kg m^2 and less).
* joint friction (Coulomb, viscous): the Panda's per-joint values (Gaz et al.'s Coulomb
  levels, PANDA_VISCOUS) over the arm's joints (interpolated along the chain for another joint
  count) times ``factor_j``; a torque ripple's amplitude and a sensor's offset times
  ``factor_j`` of their joint.
* payload mass: times the arm's moving mass (all bodies joint 1 turns) over the Panda's.
* rotor inertia: the file's armature where it has one, else ARMATURE_SHARE of the joint's mean
  inertia (a reflected rotor is of the order of the link inertia it drives).
* coupled pair (motor of joint n also turning joint n-1): fvm, fsm = the Panda-class friction of
  joint n times ``factor`` of joint n-1 (the heavier of the two drives that carry them); Iam =
  COUPLED_INERTIA_SHARE of joint n-1's rotor inertia (the TX40's Iam6 / Ia5 = 0.18), at most
  COUPLED_LOOP_GAIN / sqrt(max M^-1_n-1,n-1 max M^-1_nn): each joint's explicit Iam ddq_other
  term moves the other joint back by that loop gain per step, which must stay well below 1
  (it bites on an arm file without rotor inertias: the UR5e's wrist 3 has 2.6e-4 kg m^2).
* joint lists, as the diagnosis computes its candidates' (diagnosis/arm_dynamics_setup.py; the
  idea is copied, twins may not import the diagnosis): loaded joints (encoder offsets, ripple)
  move the gravity torque by >= LOADED_SHARE of the most sensitive joint's; scale joints
  (encoder scale's largest error) are loaded joints whose scale error (angle, rate and
  acceleration) moves the torques by >= SCALE_SHARE of the most's; inertia links move the
  torques by >= LINK_SHARE of the most's when scaled; rotor joints are all but those whose rotor
  inertia the links' own inertias take (joint 1 always; joint 2 where its axis is perpendicular
  to joint 1's: Izz1, and Izz2 with Iyy2, carry the same torque; the Panda's and TX40's Ia1, Ia2).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.sim.arm import PANDA_COULOMB_FRICTION
from serpar.sim.plants.arm_plant import ArmPlant, arm_plant
from serpar.sim.plants.moving_arm import excitation
from serpar.sim.rigid_arm import PANDA_ARM, ArmDynamics, ArmModel

Vec = NDArray[np.float64]

PANDA_VISCOUS: tuple[float, ...] = (0.2, 0.2, 0.2, 0.2, 0.1, 0.1, 0.1)
"""Viscous joint friction of a Panda-class drive at scale 1 [N m s/rad] (order of Gaz et al.)."""
LOADED_JOINTS = (1, 2, 3, 4, 5)
"""The Panda's joints 2-6 (0-based): the ones whose angle moves a gravity load or whose drive
ripples."""
SCALE_JOINTS = (1, 2, 3)
"""The Panda's joints 2-4 (0-based), one of which has encoder_scale's largest error: their
gravity load shows a scale error (20 s, s = 0.005: 2.3-8 x the noise before any fit); on
joints 5-6 even s = 0.01 reads 1.35 x (joint 5) or is taken up by an offset to 1.25 x (joint 6)."""
INERTIA_LINKS = (3, 4, 5)
"""The Panda's links a link_inertia twin may get wrong: the heavy ones (links 1-2 hardly load
the joints)."""
ROTOR_JOINTS = (3, 4, 5, 6, 7)
"""The Panda's joints an armature twin adds rotor inertia to: joint 1's and 2's are grouped with
the links' inertias (the diagnosis computes it: diagnosis/arm_dynamics_grouping.py), so no data
could name them; a twin that hid them would hide link inertia under another name."""
LOADED_SHARE = 0.03
"""Stricter than the diagnosis' 0.01 (VISIBLE_SHARE): a twin hides an error only where it
shows (the Panda's joints 2-6 lie at 0.044-1, joint 7 at 0.0007)."""
SCALE_SHARE = 0.15
"""The Panda's joints 2-4 lie at 0.32-1, joint 6 at 0.14."""
LINK_SHARE = 0.3
"""Links 1-2 of the Panda lie at 0.001-0.013, links 3-7 at 0.39-1."""
ARMATURE_SHARE = 0.5
"""Rotor inertia of a joint whose file gives none, over the joint's mean inertia (the Panda's
0.1 kg m^2 is 0.65-0.94 of its wrist joints', 0.07-0.09 of its elbow's)."""
COUPLED_INERTIA_SHARE = 0.2
COUPLED_LOOP_GAIN = 0.15
"""At magnitude 1; the largest drawn (1.5 x 1.3) stays under 0.3."""
PROBE_ROWS = 200


@dataclass(frozen=True, eq=False)
class ArmScale:
    """The twin's effects on one arm (module docstring); joints 0-based unless named."""

    plant: ArmPlant
    torque_scale: float
    factor: Vec
    coulomb: Vec
    """[N m] per joint at magnitude 1."""
    viscous: Vec
    """[N m s/rad] per joint at magnitude 1."""
    payload_scale: float
    armature: Vec
    """[kg m^2] rotor inertia of reference per joint."""
    loaded_joints: tuple[int, ...]
    scale_joints: tuple[int, ...]
    inertia_links: tuple[int, ...]
    """1-based link numbers (joint j's link is link j)."""
    rotor_joints: tuple[int, ...]
    """1-based."""
    coupled: tuple[float, float, float]
    """(Iam, fvm, fsm) of reference for the last two joints' coupled drive."""

    @property
    def arm(self) -> ArmModel:
        return self.plant.arm

    @property
    def n(self) -> int:
        return self.plant.n


def _along_chain(panda: tuple[float, ...], n: int) -> Vec:
    """The Panda's per-joint values over an n-joint chain (base to flange)."""
    return np.interp(np.linspace(0.0, len(panda) - 1.0, n), np.arange(len(panda)), panda)


def _rms_gravity(plant: ArmPlant) -> float:
    g = ArmDynamics(arm=plant.arm).gravity(plant.probe_poses())
    return float(np.sqrt(np.mean(g**2)))


def _moving_mass(arm: ArmModel) -> float:
    model = ArmDynamics(arm=arm).model
    return float(model.body_subtreemass[model.body(arm.link_bodies[0]).id])


def _shares(plant: ArmPlant) -> tuple[Vec, Vec, Vec]:
    """Per joint the gravity's sensitivity to its angle, the torques' to its scale; per link the
    torques' to its mass and inertia, each over its largest, on an excitation (fixed seed)."""
    dyn = ArmDynamics(arm=plant.arm)
    q, dq, ddq = excitation(20.0, 1000.0, np.random.default_rng(0), plant)
    rows = np.linspace(0, len(q) - 1, PROBE_ROWS).astype(int)
    q, dq, ddq = q[rows], dq[rows], ddq[rows]
    g0, tau0 = dyn.gravity(q), dyn.link_torque(q, dq, ddq)
    offset, scale = np.zeros(plant.n), np.zeros(plant.n)
    for j in range(plant.n):
        shifted = q.copy()
        shifted[:, j] += 1e-3
        offset[j] = np.abs(dyn.gravity(shifted) - g0).max() / 1e-3
        q2, v2, a2 = q.copy(), dq.copy(), ddq.copy()
        for x in (q2, v2, a2):
            x[:, j] *= 1.01
        scale[j] = np.abs(dyn.link_torque(q2, v2, a2) - tau0).max() / 0.01
    m, link = dyn.model, np.zeros(plant.n)
    for j, name in enumerate(plant.arm.link_bodies):
        b = m.body(name).id
        mass, inertia = float(m.body_mass[b]), m.body_inertia[b].copy()
        m.body_mass[b], m.body_inertia[b] = 1.1 * mass, 1.1 * inertia
        link[j] = np.sqrt(np.mean((dyn.link_torque(q, dq, ddq) - tau0) ** 2))
        m.body_mass[b], m.body_inertia[b] = mass, inertia
    return tuple(x / max(float(x.max()), 1e-300) for x in (offset, scale, link))  # type: ignore[return-value]


def _grouped_rotors(arm: ArmModel) -> set[int]:
    """0-based joints whose rotor inertia the links' inertias take (module docstring)."""
    model = ArmDynamics(arm=arm).model
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    ids = [model.joint(name).id for name in arm.joint_names]
    out = {0}
    if len(ids) > 1 and abs(float(data.xaxis[ids[0]] @ data.xaxis[ids[1]])) < 1e-6:
        out.add(1)
    return out


def _coupled_inertia(plant: ArmPlant, armature: Vec) -> float:
    a, m = plant.n - 2, plant.n - 1
    loop = float(np.sqrt(plant.coupling_gain[a, a] * plant.coupling_gain[m, m]))
    return float(min(COUPLED_INERTIA_SHARE * armature[a], COUPLED_LOOP_GAIN / loop))


@lru_cache(maxsize=8)
def arm_scale(arm: ArmModel = PANDA_ARM) -> ArmScale:
    """The twin's effect sizes on ``arm`` (cached per arm object)."""
    plant = arm_plant(arm)
    n = arm.n
    file_armature = ArmDynamics(arm=arm).armature
    armature = np.where(file_armature > 0, file_armature, ARMATURE_SHARE * plant.inertia)
    m, a = n - 1, n - 2  # the coupled motor's joint, the joint whose drive also carries it
    if arm.is_panda:
        ones = np.ones(n)
        iam = _coupled_inertia(plant, armature)
        return ArmScale(plant, 1.0, ones, np.asarray(PANDA_COULOMB_FRICTION, float),
                        np.asarray(PANDA_VISCOUS, float), 1.0, armature, LOADED_JOINTS,
                        SCALE_JOINTS, INERTIA_LINKS, ROTOR_JOINTS,
                        (iam, PANDA_VISCOUS[m], PANDA_COULOMB_FRICTION[m]))
    panda = arm_plant(PANDA_ARM)
    s = _rms_gravity(plant) / _rms_gravity(panda)
    factor = np.minimum(s, plant.inertia / float(panda.inertia.min()))
    coulomb = _along_chain(PANDA_COULOMB_FRICTION, n)
    viscous = _along_chain(PANDA_VISCOUS, n)
    offset, scale, link = _shares(plant)
    loaded = tuple(int(j) for j in np.flatnonzero(offset >= LOADED_SHARE))
    scaled = tuple(j for j in loaded if scale[j] >= SCALE_SHARE)
    grouped = _grouped_rotors(arm)
    iam = _coupled_inertia(plant, armature)
    return ArmScale(plant, float(s), factor, coulomb * factor, viscous * factor,
                    _moving_mass(arm) / _moving_mass(PANDA_ARM), armature, loaded,
                    scaled or loaded[:1],
                    tuple(int(j) + 1 for j in np.flatnonzero(link >= LINK_SHARE)),
                    tuple(j + 1 for j in range(n) if j not in grouped),
                    (float(iam), float(viscous[m] * factor[a]), float(coulomb[m] * factor[a])))
