"""A tilted base as a candidate of the arm-dynamics diagnosis (``base_tilt``): the arm stands
on a floor or a pedestal that is not level, so gravity in the arm's base frame is the file's
gravity turned by two small angles. The gravity torque is linear in the gravity vector,
g(q; gvec) = G(q) gvec, with G's columns MuJoCo's own (``mj_rne`` with a unit gravity along
each base axis), so the effect adds G(q) (gvec(alpha, beta) - gvec) on both channels (gravity
loads the links: the link-side sensors read it as the drive does), exactly, and its two
derivatives are exact too.

The angles turn the file's gravity direction as :func:`serpar.sim.tilt.tilted_gravity` says
(the twin's tilted plant turns it the same way).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.sim.rigid_arm import ArmDynamics
from serpar.sim.tilt import tilted_gravity

Vec = NDArray[np.float64]

NAME = "base_tilt"
TILT_BOUND = 0.1
"""[rad] Largest tilt searched about either axis (5.7 deg: a floor or pedestal off level by
more than that is seen by eye, not by the dynamics)."""


def tilt_effect() -> Effect:
    return Effect(NAME, "the arm's base is tilted: gravity is turned by alpha, beta in its base "
                  "frame (a floor or pedestal off level)", ("alpha", "beta"), ("rad", "rad"),
                  np.zeros(2), np.full(2, -TILT_BOUND), np.full(2, TILT_BOUND))


class BaseTilt:
    """The tilt's torques on (link, drive) at given rows, and their derivatives (a file
    without gravity has no tilt to see: :attr:`seen` is False and the torques are zero)."""

    def __init__(self, terms: Terms, dynamics: ArmDynamics) -> None:
        model = dynamics.model
        self.gravity = model.opt.gravity.copy()
        self.seen = bool(np.linalg.norm(self.gravity) > 0)
        per_axis_link, per_axis_drive = [], []
        try:
            for axis in np.eye(3):  # G(q) column by column: the torque of a unit gravity
                model.opt.gravity[:] = axis
                per_axis_link.append(dynamics.gravity(terms.q_link))
                per_axis_drive.append(dynamics.gravity(terms.q))
        finally:
            model.opt.gravity[:] = self.gravity
        self.link = np.stack(per_axis_link, axis=2)  # rows x n x 3
        self.drive = np.stack(per_axis_drive, axis=2)

    def _turned(self, angles: Vec) -> tuple[Vec, Vec]:
        if not self.seen:
            return self.gravity, np.zeros((3, 2))
        return tilted_gravity(self.gravity, angles)

    def torque(self, angles: Vec, rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """(link, drive), each rows x n [N m]."""
        change = self._turned(angles)[0] - self.gravity
        return self.link[rows] @ change, self.drive[rows] @ change

    def columns(self, angles: Vec, rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """(link, drive), each 2 x rows x n: d torque / d (alpha, beta)."""
        d = self._turned(angles)[1]  # 3 x 2
        return (np.moveaxis(self.link[rows] @ d, 2, 0), np.moveaxis(self.drive[rows] @ d, 2, 0))
