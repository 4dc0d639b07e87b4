"""The Stewart platform's quasi-static model for the diagnosis, batched over many poses: forward
kinematics from leg lengths, the leg Jacobian, and the static axial leg forces under the
platform's, the payload's and the legs' own weight. Pure numpy on arrays of poses.

Why the legs' own weight is in the statics: the joint table is near-singular (leg Jacobian
condition ~127 at home), so the 0.3 N transverse reaction with which each 0.3 kg leg leans on
its spherical joint maps to 6-11 N of axial leg force (measured against MuJoCo's servo forces
at rest); a compliance fitted to forces without it would be wrong by as much.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.sim.stewart import StewartConfig, build_stewart_spec

Vec = NDArray[np.float64]
N_LEGS = 6
FK_TOL_M = 1e-13
FK_MAX_ITER = 30


@dataclass(frozen=True)
class Load:
    """Masses the legs carry (SI), from the nominal MuJoCo model plus a known payload."""

    platform_kg: float
    platform_com: tuple[float, float, float]
    """Platform centre of mass in the platform frame [m]."""
    payload_kg: float
    payload_com: tuple[float, float, float]
    cyl_kg: float
    cyl_com: float
    """Cylinder centre of mass along the leg from its base joint [m]."""
    rod_kg: float
    rod_com: float
    """Rod centre of mass along the leg from its platform joint [m] (negative: below it)."""
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)

    @property
    def mass(self) -> float:
        return self.platform_kg + self.payload_kg

    @property
    def com(self) -> Vec:
        """Centre of mass of platform and payload, platform frame."""
        return (self.platform_kg * np.asarray(self.platform_com)
                + self.payload_kg * np.asarray(self.payload_com)) / self.mass


def nominal_load(payload_kg: float = 0.0, payload_com: tuple[float, float, float] = (0.0, 0.0, 0.0)
                 ) -> Load:
    """The masses of the default StewartConfig's MuJoCo model, plus a payload."""

    m = build_stewart_spec(StewartConfig()).compile()
    cyl, rod, plat = m.body("cyl1"), m.body("rod1"), m.body("platform")
    return Load(float(plat.mass[0]), tuple(float(v) for v in plat.ipos), float(payload_kg),
                tuple(float(v) for v in payload_com), float(cyl.mass[0]), float(cyl.ipos[2]),
                float(rod.mass[0]), float(rod.ipos[2]), tuple(float(v) for v in m.opt.gravity))


def so3_exp_batch(w: Vec) -> Vec:
    """exp([w]x) for (n, 3) rotation vectors (Rodrigues, series below 1e-8 rad)."""
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    k = np.zeros(w.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = w[..., 2], -w[..., 1], w[..., 0]
    small = th < 1e-8
    safe = np.where(small, 1.0, th)
    a = np.where(small, 1.0, np.sin(safe) / safe)
    b = np.where(small, 0.5, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * k + b * (k @ k)


def so3_log_batch(rot: Vec) -> Vec:
    """Rotation vectors (n, 3) of rotation matrices (n, 3, 3) (angles well below pi)."""
    skew = np.stack([rot[..., 2, 1] - rot[..., 1, 2], rot[..., 0, 2] - rot[..., 2, 0],
                     rot[..., 1, 0] - rot[..., 0, 1]], axis=-1)
    s = 0.5 * np.linalg.norm(skew, axis=-1)
    c = 0.5 * (np.trace(rot, axis1=-2, axis2=-1) - 1.0)
    th = np.arctan2(s, c)
    scale = np.where(s < 1e-12, 0.5, th / (2.0 * np.where(s < 1e-12, 1.0, s)))
    return skew * scale[..., None]


def leg_vectors(P: Vec, B: Vec, pos: Vec, rot: Vec) -> Vec:
    """(n, 6, 3) base joint -> platform joint, base frame. P, B: (6, 3) or (n, 6, 3)."""
    rp = np.einsum("nij,n...kj->n...ki", rot, np.broadcast_to(P, (len(pos),) + np.shape(P)[-2:]))
    return pos[:, None, :] + rp - B


def pose_jacobian(P: Vec, B: Vec, pos: Vec, rot: Vec) -> tuple[Vec, Vec, Vec]:
    """d(leg length)/d(twist) (n, 6, 6) with twist (v, w) in the base frame; also the unit
    leg vectors (n, 6, 3) and the lengths (n, 6)."""
    legs = leg_vectors(P, B, pos, rot)
    length = np.linalg.norm(legs, axis=-1)
    u = legs / length[..., None]
    rp = legs - pos[:, None, :] + B
    return np.concatenate([u, np.cross(rp, u)], axis=-1), u, length


def forward_kinematics(P: Vec, B: Vec, L: Vec, pos0: Vec, rot0: Vec) -> tuple[Vec, Vec]:
    """Poses (n, 3), (n, 3, 3) whose leg lengths are L (n, 6), by Newton from (pos0, rot0)
    (the measured poses: within a millimetre, three iterations)."""
    pos, rot = np.array(pos0, float), np.array(rot0, float)
    for _ in range(FK_MAX_ITER):
        jac, _, length = pose_jacobian(P, B, pos, rot)
        res = length - L
        if np.max(np.abs(res)) < FK_TOL_M:
            return pos, rot
        step = np.linalg.solve(jac, -res[..., None])[..., 0]
        pos = pos + step[:, :3]
        rot = so3_exp_batch(step[:, 3:]) @ rot
    raise IdentificationError(f"Stewart forward kinematics did not converge (leg residual "
                              f"{np.max(np.abs(res)):.3g} m): leg lengths and platform poses "
                              "do not belong to one platform")


def static_leg_forces(P: Vec, B: Vec, pos: Vec, rot: Vec, load: Load) -> Vec:
    """(n, 6) axial force each actuator carries at rest [N], positive pushing the leg out:
    the platform's and payload's weight, each leg leaning on its spherical joint with its own
    weight's moment about the universal joint, and the rod's weight along its axis."""
    g = np.asarray(load.gravity, float)
    jac, u, length = pose_jacobian(P, B, pos, rot)
    rp = u * length[..., None] - pos[:, None, :] + B  # R P_i
    # moment of each leg's weight about its base joint; the ball joint carries the part
    # perpendicular to the leg (the universal joint carries the part about the leg axis)
    lever = load.cyl_kg * load.cyl_com + load.rod_kg * (length + load.rod_com)  # (n, 6)
    moment = lever[..., None] * np.cross(u, g)
    f_perp = np.cross(u, moment) / length[..., None]  # force of the platform on each leg
    weight = load.mass * g
    com = np.einsum("nij,j->ni", rot, load.com)
    wrench = np.concatenate([weight - f_perp.sum(axis=1),
                             np.cross(com, weight) - np.cross(rp, f_perp).sum(axis=1)], axis=-1)
    f = np.linalg.solve(np.swapaxes(jac, -1, -2), -wrench[..., None])[..., 0]
    return f - load.rod_kg * (u @ g)
