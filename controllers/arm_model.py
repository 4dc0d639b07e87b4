"""The arm as one controller sees it: :class:`BatchNominalArm` at N = 1 with one arm's shapes.

The nominal model, its terms and the momentum observer's terms exist once, over a batch axis
(controllers/batch_model.py); this view loads a (7,) state and returns (3,) / (3, 3) / (6, 7)
arrays, for the one-arm controller and for code that only needs the arm's forward kinematics
(camera and in-hand calibration views).
"""

from __future__ import annotations

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.controllers.batch_model import BatchNominalArm
from serpar.errors import ConfigError, LimitError
from serpar.sim.arm import N_JOINTS, Q_MAX, Q_MIN

Vec = NDArray[np.float64]


class NominalArm:
    """The controller's dynamic model of one arm, evaluated at the measured state."""

    def __init__(self, model: mujoco.MjModel | None = None,
                 batch: BatchNominalArm | None = None) -> None:
        """`batch`: a batch of one to view (a controller's own); else one on `model` (default
        the arm's MJCF)."""
        if batch is not None and batch.n != 1:
            raise ConfigError(f"NominalArm views a batch of one, got n={batch.n}")
        self.batch = BatchNominalArm(1, model) if batch is None else batch
        self.model, self.index = self.batch.model, self.batch.index

    def load(self, q: Vec, dq: Vec) -> None:
        """Evaluate kinematics, mass matrix and bias forces at (q, dq)."""
        self.batch.load(np.reshape(q, (1, N_JOINTS)), np.reshape(dq, (1, N_JOINTS)))

    def tcp_pose(self) -> tuple[Vec, Vec]:
        """TCP position [m] and rotation matrix in the arm base frame (copies)."""
        pos, rot = self.batch.tcp_pose()
        return pos[0], rot[0]

    def tcp_jacobian(self) -> Vec:
        """6x7 geometric Jacobian of the TCP (linear rows first)."""
        return self.batch.tcp_jacobian()[0]

    def mass(self) -> Vec:
        """7x7 joint-space inertia including rotor armature."""
        return self.batch.mass()[0]

    def bias(self) -> Vec:
        """c(q, dq) + g(q) plus the model's viscous joint friction [N m]."""
        return self.batch.bias()[0]


def require_joint_target(q: Vec) -> Vec:
    """Raise LimitError naming the joint and its range when q is outside the Panda limits."""
    q = np.asarray(q, dtype=float).reshape(-1)
    if q.shape != (N_JOINTS,):
        raise ConfigError(f"joint target needs {N_JOINTS} angles, got shape {q.shape}")
    for i, (v, lo, hi) in enumerate(zip(q, Q_MIN, Q_MAX)):
        if not lo <= v <= hi:
            raise LimitError(f"joint{i + 1} target {v:.4f} rad outside its limit [{lo}, {hi}] rad")
    return q
