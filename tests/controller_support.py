"""Shared by the controller tests: rotations built with MuJoCo's own quaternion maths, so that
targets are bit-identical to those the reference fixture (tests/data/) was recorded with."""

from __future__ import annotations

import mujoco
import numpy as np


def rotation(rotvec: np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (axis * angle), through mju_axisAngle2Quat."""
    quat, mat = np.zeros(4), np.zeros(9)
    angle = float(np.linalg.norm(rotvec))
    mujoco.mju_axisAngle2Quat(quat, rotvec / angle, angle)
    mujoco.mju_quat2Mat(mat, quat)
    return mat.reshape(3, 3)
