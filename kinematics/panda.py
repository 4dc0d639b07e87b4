"""The Franka Panda's nominal kinematics and joint limits: the published modified-DH (Craig)
table and flange offset, so that real Panda recordings line up with the model
(``assets/arm/panda.xml``'s body frames coincide with these DH frames; tests/test_arm.py reads
the numbers back from the compiled model)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError

N_JOINTS = 7

Q_MIN: tuple[float, ...] = (-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973)
Q_MAX: tuple[float, ...] = (2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973)

# Modified DH (Craig): frame i = RotX(alpha_{i-1}) TransX(a_{i-1}) RotZ(q_i) TransZ(d_i).
MDH_A: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088)
MDH_D: tuple[float, ...] = (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0)
MDH_ALPHA: tuple[float, ...] = (0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2,
                                math.pi / 2, math.pi / 2)
FLANGE_D = 0.107



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
