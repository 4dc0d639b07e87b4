"""The 7-DoF Franka-Panda-like arm: asset path, names, limits and nominal kinematics.

This module is the single source of truth for the arm's names and limits; the
MJCF in ``assets/arm/panda.xml`` must agree with it (``tests/test_arm.py``
reads the numbers back from the compiled model). The kinematics are the
Panda's published modified-DH (Craig) table, so real Panda recordings line up
with the model; the MJCF body frames coincide with these DH frames.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from assets import asset_path
from sim.errors import ConfigError

ARM_XML = asset_path("arm", "panda.xml")

N_JOINTS = 7

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
Q_MIN: tuple[float, ...] = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
Q_MAX: tuple[float, ...] = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)

PANDA_COULOMB_FRICTION: tuple[float, ...] = tuple(phi / 2 for phi in (
    0.54615, 0.87224, 0.64068, 1.2794, 0.83904, 0.30301, 0.56489))
"""Dry joint friction of a real Panda [N m]: half the swing phi_1 of the sigmoid friction model
identified by Gaz et al. (IEEE RA-L 2019, "Dynamic identification of the Franka Emika Panda"),
i.e. its level at speed on either side of zero."""

LINK_NAMES: tuple[str, ...] = tuple(f"link{i}" for i in range(8))
HAND_BODY = "hand"
FINGER_BODIES: tuple[str, str] = ("finger_left", "finger_right")
FINGER_JOINT_NAMES: tuple[str, str] = ("finger_left", "finger_right")
FINGER_CARRIER_BODY = "finger_carrier"
GRIP_COMPLIANCE_JOINT = "grip_compliance"
"""Axial spring of the compliant gripper (fingers on the hand, along the approach axis)."""
PAD_GEOMS: tuple[str, str] = ("pad_left", "pad_right")
FINGER_EQUALITY = "finger_coupling"
GRIP_ACTUATOR = "grip"
GRIP_FORCE_MAX = 70.0
"""Franka Hand continuous grasp force [N]; ctrl of ``grip`` is the squeeze per pad."""
FINGER_OPENING_MAX = 0.04
"""Travel of each finger [m] (jaw width 0..80 mm)."""
FLANGE_SITE = "flange"
TCP_SITE = "tcp"
TCP_OFFSET = 0.1034
"""Flange-to-grasp-point distance [m] along the flange z (Franka Hand default EE frame)."""

# Modified DH (Craig): frame i = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(q_i) TransZ(d_i).
MDH_A: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088)
MDH_D: tuple[float, ...] = (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0)
MDH_ALPHA: tuple[float, ...] = (0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2,
                                math.pi / 2, math.pi / 2)
FLANGE_D = 0.107


def build_arm_spec() -> mujoco.MjSpec:
    """A fresh, editable spec of the arm (attach it into a scene with a prefix)."""
    return mujoco.MjSpec.from_file(str(ARM_XML))


def mdh_transform(a: float, d: float, alpha: float, theta: float) -> NDArray[np.float64]:
    """One modified-DH link transform RotX(alpha) TransX(a) RotZ(theta) TransZ(d)."""
    ca, sa = math.cos(alpha), math.sin(alpha)
    ct, st = math.cos(theta), math.sin(theta)
    return np.array(
        [
            [ct, -st, 0.0, a],
            [st * ca, ct * ca, -sa, -sa * d],
            [st * sa, ct * sa, ca, ca * d],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def mdh_forward_kinematics(
    q: Sequence[float] | NDArray[np.float64],
    a: Sequence[float] = MDH_A,
    d: Sequence[float] = MDH_D,
    alpha: Sequence[float] = MDH_ALPHA,
    flange_d: float = FLANGE_D,
) -> NDArray[np.float64]:
    """Flange pose (4x4, arm base frame) from the MDH table.

    The table is a parameter so calibration code can pass perturbed values;
    the defaults are the Panda's nominal kinematics.
    """
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (N_JOINTS,):
        raise ConfigError(f"q must have {N_JOINTS} joint angles, got shape {q.shape}")
    if not (len(a) == len(d) == len(alpha) == N_JOINTS):
        raise ConfigError(f"MDH table rows must each have {N_JOINTS} entries")
    pose = np.eye(4)
    for i in range(N_JOINTS):
        pose = pose @ mdh_transform(a[i], d[i], alpha[i], float(q[i]))
    # flange: pure translation along z7 (alpha = a = theta = 0)
    return pose @ mdh_transform(0.0, flange_d, 0.0, 0.0)
