"""Joint friction in the published Panda form (Gaz et al. 2019, :data:`serpar.sim.arm.GAZ_FRICTION_PHI`):
a sigmoid in the joint speed with an offset, which MuJoCo's ``frictionloss`` (one dry level,
symmetric, a constraint) cannot express. It acts as a joint torque the drive loses,
``qfrc_applied = -tau_f(dq)``, set before every physics substep from the speed at its start
(explicit: its steepest slope, phi_1 phi_2 / 4 <= 3.6 N m s/rad at 3x a real Panda's, is
well below what a 0.1 ms step integrates stably against the joints' armature). The link-side
torque sensors read it as MuJoCo's joint friction: through the motion, as drive friction.

At speed it is Coulomb's law with level phi_1 / 2 about an offset of about -phi_1 phi_2 phi_3 / 4
(the sigmoid is centred on -phi_3), and it passes through zero torque at rest: below ~1 / phi_2
rad/s (0.06-0.2 rad/s) it is a viscous-like slope, not a sticking dry friction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.special import expit

from serpar.errors import ConfigError
from serpar.sim.arm import GAZ_FRICTION_PHI, JOINT_NAMES

Vec = NDArray[np.float64]
MAX_SCALE = 5.0


def gaz_friction_torque(dq: Vec, scale: float = 1.0) -> Vec:
    """tau_f(dq) of Gaz et al.'s model times ``scale`` [N m] (the drive loses it)."""
    phi1, phi2, phi3 = (np.asarray(p) for p in GAZ_FRICTION_PHI)
    return scale * phi1 * (expit(phi2 * (dq + phi3)) - expit(phi2 * phi3))


def gaz_levels(scale: float = 1.0) -> tuple[Vec, Vec]:
    """Per joint its Coulomb level at speed and the offset it is centred on [N m]:
    tau_f(+inf) = offset + level, tau_f(-inf) = offset - level."""
    phi1, phi2, phi3 = (np.asarray(p) for p in GAZ_FRICTION_PHI)
    level = scale * phi1 / 2.0
    return level, level - scale * phi1 * expit(phi2 * phi3)


@dataclass
class DriveFriction:
    """Sets the arm's drive friction torque in ``qfrc_applied`` before each substep."""

    dofs: NDArray[np.int64]
    scale: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and 0 < self.scale <= MAX_SCALE):
            raise ConfigError(f"drive friction scale {self.scale}: valid 0 < scale <= {MAX_SCALE} "
                              "(times a real Panda's)")

    @classmethod
    def of_arm(cls, model: mujoco.MjModel, prefix: str, scale: float) -> DriveFriction:
        dofs = np.array([model.joint(prefix + n).dofadr[0] for n in JOINT_NAMES])
        return cls(dofs, float(scale))

    def __call__(self, data: mujoco.MjData) -> None:
        data.qfrc_applied[self.dofs] = -gaz_friction_torque(data.qvel[self.dofs], self.scale)
