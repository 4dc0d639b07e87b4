"""Joint friction inside the drive that MuJoCo has no element for: the published Panda form
(Gaz et al. 2019, :data:`serpar.sim.arm.GAZ_FRICTION_PHI`), a sigmoid in the joint speed with
an offset, and a Stribeck fall above the Coulomb level. MuJoCo's ``frictionloss`` is one dry
level, symmetric, a constraint: it expresses neither. They act as a joint torque the drive
loses, ``qfrc_applied = -tau_f(dq)``, set before every physics substep from the speed at its
start. The link-side torque sensors read it as MuJoCo's joint friction: through the motion,
as drive friction.

The sigmoid at speed is Coulomb's law with level phi_1 / 2 about an offset of about
-phi_1 phi_2 phi_3 / 4 (the sigmoid is centred on -phi_3), and it passes through zero torque
at rest: below ~1 / phi_2 rad/s it is a viscous-like slope, not a sticking dry friction. Its
steepest slope, phi_1 phi_2 / 4 (<= 3.6 N m s/rad at 3x a real Panda's), is well below what
the cell's steps integrate stably against the joints' inertia: explicit.

The Stribeck fall dFs exp(-(v / vs)^2) against the motion is static friction above the
Coulomb level: it is set as the joints' dry friction level, MuJoCo's ``frictionloss`` =
Fc + dFs exp(-(v / vs)^2) at the speed of each substep's start, so the solver holds a joint
at rest up to Fs = Fc + dFs and lets it slide at the Coulomb level once it moves. As an
explicit torque it would need a smoothed sign whose slope at rest (dFs / width, hundreds of
N m s/rad) drives the arm against the pads' stiff grip on a 1.7 g conductor: the cell's
grasps blew up so (while the hand still squeezed at once; not tried again since it closes at its
own speed, controllers/gripper_servo.py). (The arm-dynamics twin, which grips nothing, keeps the
smoothed torque:
:func:`stribeck_fall_torque`.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.special import expit

from serpar.errors import ConfigError
from serpar.sim.arm import GAZ_FRICTION_PHI, JOINT_NAMES, N_JOINTS

Vec = NDArray[np.float64]
Phi = tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]
MAX_SCALE = 5.0
STRIBECK_SMOOTHING = 1e-3
"""[rad/s] Narrowest width of the Stribeck fall's smoothed sign, tanh(v / width)."""
MAX_LEVEL = 20.0  # [N m] as ArmPlantChanges' frictionloss
STEEPNESS = (1e-3, 100.0)  # [s/rad] phi2 (the diagnosis's bounds: 1 .. 100)
MAX_SHIFT = 1.0  # [rad/s] |phi3|
SPEEDS = (1e-4, 10.0)  # [rad/s] a Stribeck speed


def sigmoid_friction_torque(dq: Vec, phi1: Vec, phi2: Vec, phi3: Vec) -> Vec:
    """tau_f(dq) = phi1 (sigma(phi2 (dq + phi3)) - sigma(phi2 phi3)) [N m] (the drive loses it)."""
    return phi1 * (expit(phi2 * (dq + phi3)) - expit(phi2 * phi3))


def stribeck_fall_torque(dq: Vec, excess: Vec, speed: Vec, width: Vec) -> Vec:
    """dFs exp(-(dq / vs)^2) tanh(dq / w) [N m] (the drive loses it)."""
    x = dq * (1.0 / speed)
    return excess * np.exp(-x * x) * np.tanh(dq * (1.0 / width))


def gaz_friction_torque(dq: Vec, scale: float = 1.0) -> Vec:
    """tau_f(dq) of Gaz et al.'s model times ``scale`` [N m] (the drive loses it)."""
    phi1, phi2, phi3 = (np.asarray(p) for p in GAZ_FRICTION_PHI)
    return sigmoid_friction_torque(dq, scale * phi1, phi2, phi3)


def gaz_levels(scale: float = 1.0) -> tuple[Vec, Vec]:
    """Per joint its Coulomb level at speed and the offset it is centred on [N m]:
    tau_f(+inf) = offset + level, tau_f(-inf) = offset - level."""
    phi1, phi2, phi3 = (np.asarray(p) for p in GAZ_FRICTION_PHI)
    level = scale * phi1 / 2.0
    return level, level - scale * phi1 * expit(phi2 * phi3)


def gaz_sigmoid_params(scale: float = 1.0) -> dict[str, float]:
    """Gaz et al.'s friction at ``scale`` x a real Panda's in the diagnosis's
    ``sigmoid_friction`` names: phi1_j the swing (scaled), phi2_j, phi3_j their own."""
    phi1, phi2, phi3 = GAZ_FRICTION_PHI
    return {**{f"phi1_{j + 1}": scale * v for j, v in enumerate(phi1)},
            **{f"phi2_{j + 1}": float(v) for j, v in enumerate(phi2)},
            **{f"phi3_{j + 1}": float(v) for j, v in enumerate(phi3)}}


def _per_joint(name: str, values: tuple[float, ...], lo: float, hi: float) -> None:
    if len(values) != N_JOINTS or not all(math.isfinite(v) and lo <= v <= hi for v in values):
        raise ConfigError(f"drive friction {name} {tuple(values)}: {N_JOINTS} finite values in "
                          f"{lo:g}..{hi:g}")


@dataclass(frozen=True)
class DriveFrictionLaw:
    """Per joint the drive friction beyond MuJoCo's: sigmoid terms (each phi1, phi2, phi3 of
    N_JOINTS values; several add) and a Stribeck fall (dFs, vs per joint; () for none)."""

    sigmoids: tuple[Phi, ...] = ()
    stribeck_excess: tuple[float, ...] = ()
    """dFs = Fs - Fc per joint [N m]."""
    stribeck_speed: tuple[float, ...] = ()
    """vs per joint [rad/s]."""

    def __post_init__(self) -> None:
        for phi1, phi2, phi3 in self.sigmoids:
            _per_joint("phi1", phi1, 0.0, 2 * MAX_LEVEL)
            _per_joint("phi2", phi2, *STEEPNESS)
            _per_joint("phi3", phi3, -MAX_SHIFT, MAX_SHIFT)
        if self.stribeck_excess or self.stribeck_speed:
            _per_joint("dFs", self.stribeck_excess, 0.0, MAX_LEVEL)
            _per_joint("vs", self.stribeck_speed, *SPEEDS)

    @classmethod
    def gaz(cls, scale: float) -> DriveFrictionLaw:
        """Gaz et al.'s identified Panda friction at ``scale`` x a real Panda's."""
        if not (math.isfinite(scale) and 0 < scale <= MAX_SCALE):
            raise ConfigError(f"drive friction scale {scale}: valid 0 < scale <= {MAX_SCALE} "
                              "(times a real Panda's)")
        phi1, phi2, phi3 = GAZ_FRICTION_PHI
        return cls(sigmoids=((tuple(scale * v for v in phi1), phi2, phi3),))

    def plus(self, other: DriveFrictionLaw) -> DriveFrictionLaw:
        """Both laws acting together (their Stribeck falls may not both be set)."""
        if self.stribeck_excess and other.stribeck_excess:
            raise ConfigError("two Stribeck falls on one drive: give one")
        return DriveFrictionLaw(self.sigmoids + other.sigmoids,
                                self.stribeck_excess or other.stribeck_excess,
                                self.stribeck_speed or other.stribeck_speed)

    def __bool__(self) -> bool:
        return bool(self.sigmoids or self.stribeck_excess)

    def words(self) -> str:
        return " + ".join(["sigmoid"] * bool(self.sigmoids) + ["Stribeck"] * bool(self.stribeck_excess))


@dataclass
class DriveFriction:
    """The arm's drive friction, set before each substep: the sigmoid as a torque in
    ``qfrc_applied``, the Stribeck fall as the joints' dry friction level (``frictionloss``)."""

    model: mujoco.MjModel
    dofs: NDArray[np.int64]
    law: DriveFrictionLaw
    base_loss: Vec
    """The joints' compiled ``frictionloss`` [N m]: the Coulomb level the fall rises above."""

    def __post_init__(self) -> None:
        self._phi = [tuple(np.asarray(p, float) for p in s) for s in self.law.sigmoids]
        self._excess = np.asarray(self.law.stribeck_excess, float)
        self._inv_speed = 1.0 / np.asarray(self.law.stribeck_speed, float)

    @classmethod
    def of_arm(cls, model: mujoco.MjModel, prefix: str, law: DriveFrictionLaw,
               longest_step: float) -> DriveFriction:
        """The arm's drive friction; ``longest_step`` [s]: the longest physics step the cell
        takes (its transit step), which the explicit sigmoid must stay stable at."""
        dofs = np.array([model.joint(prefix + n).dofadr[0] for n in JOINT_NAMES])
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        full = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, full)
        inertia = np.diag(full)[dofs]
        slope = sum(np.asarray(p1) * np.asarray(p2) / 4.0 for p1, p2, _ in law.sigmoids)
        unstable = np.flatnonzero(slope * longest_step / inertia >= 1.0)
        if unstable.size:
            j = int(unstable[0])
            raise ConfigError(f"drive friction on joint {j + 1}: the sigmoid's slope at rest, "
                              f"{float(slope[j]):.3g} N m s/rad, is too steep for the cell's "
                              f"{longest_step * 1e3:g} ms step against {inertia[j]:.3g} kg m^2 "
                              "(valid: phi1 phi2 / 4 < inertia / step)")
        return cls(model, dofs, law, model.dof_frictionloss[dofs].copy())

    def torque(self, dq: Vec) -> Vec:
        """What the sigmoids take from the drives at joint speeds ``dq`` [N m]."""
        out = np.zeros(len(dq))
        for phi1, phi2, phi3 in self._phi:
            out += sigmoid_friction_torque(dq, phi1, phi2, phi3)
        return out

    def dry_level(self, dq: Vec) -> Vec:
        """The joints' dry friction level at speeds ``dq`` [N m]: Fc + dFs exp(-(dq/vs)^2)."""
        if not self._excess.size:
            return self.base_loss
        x = dq * self._inv_speed
        return self.base_loss + self._excess * np.exp(-x * x)

    def __call__(self, data: mujoco.MjData) -> None:
        dq = data.qvel[self.dofs]
        if self._phi:
            data.qfrc_applied[self.dofs] = -self.torque(dq)
        if self._excess.size:
            self.model.dof_frictionloss[self.dofs] = self.dry_level(dq)
