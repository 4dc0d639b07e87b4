"""The 7-DoF Franka-Panda-like arm in MuJoCo: asset path, names, torque limits, friction.

This module is the single source of truth for the arm's names and limits; the
MJCF in ``assets/arm/panda.xml`` must agree with it (``tests/test_arm.py``
reads the numbers back from the compiled model). The kinematics and joint
limits are :mod:`serpar.kinematics.panda` (the Panda's published modified-DH table), so real
Panda recordings line up with the model; the MJCF body frames coincide with these DH frames.
"""

from __future__ import annotations

import mujoco

from serpar.assets import asset_path
from serpar.kinematics.panda import (  # noqa: F401  (the arm's numbers, read through here by sim)
    FLANGE_D,
    MDH_A,
    MDH_ALPHA,
    MDH_D,
    N_JOINTS,
    Q_MAX,
    Q_MIN,
    mdh_forward_kinematics,
    mdh_transform,
)

ARM_XML = asset_path("arm", "panda.xml")

HOME_Q: tuple[float, ...] = (0.0, -0.785398, 0.0, -2.356194, 0.0, 1.570796, 0.785398)
"""Panda "ready" pose [rad]: flange pointing straight down in front of the base."""

JOINT_NAMES: tuple[str, ...] = tuple(f"joint{i}" for i in range(1, 8))
ACTUATOR_NAMES: tuple[str, ...] = tuple(f"tau{i}" for i in range(1, 8))
TORQUE_SENSOR_NAMES: tuple[str, ...] = tuple(f"tau_J{i}" for i in range(1, 8))
"""Torque sensors (3-vectors); the joint torque is component :data:`TORQUE_AXIS`."""
TORQUE_SITE_NAMES: tuple[str, ...] = tuple(f"tau_site{i}" for i in range(1, 8))
TORQUE_AXIS = 2
"""Index of the joint-axis component in each torque sensor's 3-vector (site z)."""

TORQUE_LIMITS: tuple[float, ...] = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)
"""Symmetric joint torque limits [N m] (Franka datasheet)."""
GAZ_FRICTION_PHI: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]] = (
    (0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489),
    (5.1181, 9.0657, 10.136, 5.5903, 8.3469, 17.133, 10.336),
    (0.039533, 0.025882, -0.04607, 0.036194, 0.026226, -0.021047, 0.0035526))
"""The joint friction of a real Panda as Gaz et al. identified it (IEEE RA-L 2019, "Dynamic
identification of the Franka Emika Panda Robot With Retrieval of Feasible Parameters Using
Penalty-Based Optimization"; their published model code): per joint phi_1 [N m], phi_2
[s/rad], phi_3 [rad/s] of tau_f = phi_1 / (1 + exp(-phi_2 (dq + phi_3))) - phi_1 / (1 +
exp(-phi_2 phi_3)), the torque the drive loses to friction."""
PANDA_COULOMB_FRICTION: tuple[float, ...] = tuple(phi / 2 for phi in GAZ_FRICTION_PHI[0])
"""Dry joint friction of a real Panda [N m]: half the swing phi_1 of Gaz et al.'s sigmoid,
i.e. its level at speed on either side of zero."""

LINK_NAMES: tuple[str, ...] = tuple(f"link{i}" for i in range(8))
HAND_BODY = "hand"
FINGER_BODIES: tuple[str, str] = ("finger_left", "finger_right")
FINGER_JOINT_NAMES: tuple[str, str] = ("finger_left", "finger_right")
FINGER_CARRIER_BODY = "finger_carrier"
GRIP_COMPLIANCE_JOINT = "grip_compliance"
"""Axial spring of the compliant gripper (fingers on the hand, along the approach axis)."""
PAD_GEOMS: tuple[str, str] = ("pad_left", "pad_right")
PAD_CONTYPE = 4
"""contype of the pads (conaffinity 1): they touch default world geoms and the conductors'
journals and tips from the collision bits, but a conductor's body (contype 2, conaffinity 3,
:mod:`serpar.sim.collision`) only through the explicit pad pairs the scene adds
(:func:`serpar.sim.contact.add_pad_pairs`), which carry the pads' own friction damping."""
FINGER_EQUALITY = "finger_coupling"
GRIP_ACTUATOR = "grip"
GRIP_FORCE_MAX = 70.0
"""Franka Hand continuous grasp force [N]; ctrl of ``grip`` is the squeeze per pad."""
FINGER_OPENING_MAX = 0.04
"""Travel of each finger [m] (jaw width 0..80 mm)."""
FLANGE_SITE = "flange"
TCP_SITE = "tcp"
BASE_BODY = "link0"
"""The arm's root body (its base, fixed where the arm is attached)."""
TCP_OFFSET = 0.1034
"""Flange-to-grasp-point distance [m] along the flange z (Franka Hand default EE frame)."""

def build_arm_spec() -> mujoco.MjSpec:
    """A fresh, editable spec of the arm (attach it into a scene with a prefix)."""
    return mujoco.MjSpec.from_file(str(ARM_XML))
