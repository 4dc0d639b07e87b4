"""Any serial revolute arm's nominal kinematics and joint limits (:class:`Robot`), and the exact
conversion of its joint axes at q = 0 into seed 003's MD-H(+beta) table (:func:`mdh_from_axes`).

Why MD-H(+beta) and not the POE form, although the joint axes and anchors at q = 0 are
directly the POE screws: the static calibration takes either form, but the arm-static
diagnosis (its geometric and thermal effects, the rank test, the parameter names ``j3.a``)
works on the elementary-motion :class:`serpar.kinematics.mdh.Chain`, and the POE chain is built
from the MD-H table in one line (``serpar.calibration.poe_calibration.robot_poe_chain``), not
the other way round. The conversion is exact (Craig's common-normal construction), so the two
forms still give the same nominal forward kinematics.

Conventions (:mod:`serpar.kinematics.mdh`): joint i is ``RotX(alpha) TransX(a) RotZ(theta + q)
TransZ(d) RotY(beta)``; the base frame (6) comes before joint 1 and the flange frame (6: a
translation, then X-Y-Z rotations) after joint n. Nominal beta is zero: the construction
places every axis exactly with alpha and a, so beta is only an error parameter (seed 003 uses
it where consecutive axes are parallel and a small tilt would make d jump).
Where the common normal is not unique (parallel or coincident axes) the one through the
model's own body origin is taken, and the sign of each x axis follows the model's body x
axis, so a model drawn in MD-H frames (the Panda's MJCF) reads back its own table (theta = 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.mdh import FRAME_PARAMS, LINK_PARAMS, Chain, elementary
from serpar.kinematics.panda import FLANGE_D, MDH_A, MDH_ALPHA, MDH_D, Q_MAX, Q_MIN

Array = NDArray[np.float64]

_LINK_KINDS = ("rx", "tx", "rz", "tz", "ry")
PARALLEL_TOL = 1e-9
"""|sin| of the angle between two axes below which they are treated as parallel."""
INTERSECT_TOL_M = 1e-12
"""A common normal shorter than this is zero: the axes intersect (its direction is then z x u)."""


@dataclass(frozen=True)
class Robot:
    """A serial arm of revolute joints: its nominal MD-H(+beta) table, joint limits [rad] and
    where they come from (``source``: the model file, or ``built-in``)."""

    name: str
    base: tuple[float, ...]
    """Base frame in the measurement (world) frame: tx, ty, tz [m], rx, ry, rz [rad]."""
    links: tuple[tuple[float, ...], ...]
    """Per joint: alpha [rad], a [m], theta [rad], d [m], beta [rad]."""
    flange: tuple[float, ...]
    """Flange frame in the last joint's frame: tx, ty, tz [m], rx, ry, rz [rad]."""
    q_min: tuple[float, ...]
    q_max: tuple[float, ...]
    source: str = "built-in"

    def __post_init__(self) -> None:
        n = len(self.links)
        if n < 1 or any(len(row) != len(LINK_PARAMS) for row in self.links):
            raise ConfigError(f"robot {self.name}: links must be n >= 1 rows of "
                              f"{', '.join(LINK_PARAMS)}")
        if len(self.base) != 6 or len(self.flange) != 6:
            raise ConfigError(f"robot {self.name}: base and flange must be 6 values "
                              f"({', '.join(FRAME_PARAMS)})")
        if len(self.q_min) != n or len(self.q_max) != n:
            raise ConfigError(f"robot {self.name}: {n} joints but {len(self.q_min)} lower and "
                              f"{len(self.q_max)} upper limits")
        values = np.r_[self.base, np.ravel(self.links), self.flange, self.q_min, self.q_max]
        if not np.all(np.isfinite(values)):
            raise ConfigError(f"robot {self.name}: kinematics and limits must be finite")
        bad = [j + 1 for j in range(n) if not self.q_min[j] < self.q_max[j]]
        if bad:
            raise ConfigError(f"robot {self.name}: joint(s) {bad} have lower limit >= upper")

    @property
    def n_joints(self) -> int:
        return len(self.links)

    @property
    def label(self) -> str:
        """How messages name the arm: ``panda`` or ``iiwa14 (from FILE)``."""
        return self.name if self.source == "built-in" else f"{self.name} (from {self.source})"

    @property
    def other_arm_hint(self) -> str:
        """What a message about a mismatch adds for the default arm: the data may be another's."""
        return "; another arm: give its URDF/MJCF with --robot FILE" if self.source == "built-in" else ""

    def chain(self, tool_offset: Sequence[float] = (0.0, 0.0, 0.0)) -> Chain:
        """The MD-H(+beta) chain with its tool point ``tool_offset`` [m] in the flange frame:
        base (6), five parameters per joint, tool (6), named like
        :func:`serpar.kinematics.mdh.panda_chain`'s."""
        tool = np.asarray(tool_offset, float).reshape(-1)
        if tool.shape != (3,) or not np.all(np.isfinite(tool)):
            raise ConfigError(f"tool_offset must be 3 finite numbers [m], got {tool_offset!r}")
        flange = frame_transform(self.flange)
        tool_t = flange[:3, 3] + flange[:3, :3] @ tool
        names = [f"base.{p}" for p in FRAME_PARAMS]
        kinds = list(FRAME_PARAMS)
        nominal = list(self.base)
        joint = [-1] * 6
        for i, row in enumerate(self.links):
            names += [f"j{i + 1}.{p}" for p in LINK_PARAMS]
            kinds += _LINK_KINDS
            nominal += list(row)
            joint += [i if p == "theta" else -1 for p in LINK_PARAMS]
        names += [f"tool.{p}" for p in FRAME_PARAMS]
        kinds += FRAME_PARAMS
        nominal += [*tool_t, *self.flange[3:]]
        joint += [-1] * 6
        return Chain(tuple(names), tuple(kinds), tuple(float(v) for v in nominal),
                     tuple(joint), self.n_joints)


def panda_robot() -> Robot:
    """The Franka Panda from :mod:`serpar.kinematics.panda` (the default arm everywhere)."""
    links = tuple((MDH_ALPHA[i], MDH_A[i], 0.0, MDH_D[i], 0.0) for i in range(len(MDH_A)))
    return Robot("panda", (0.0,) * 6, links, (0.0, 0.0, FLANGE_D, 0.0, 0.0, 0.0), Q_MIN, Q_MAX)


PANDA = panda_robot()


def frame_transform(p: Sequence[float]) -> Array:
    """4x4 of a base/tool frame's six values: TransXYZ(tx, ty, tz) RotX RotY RotZ."""
    t = np.eye(4)
    for kind, v in zip(FRAME_PARAMS, p):
        t = t @ elementary(kind, np.array([v]))[0]
    return t


def frame_params(t: Array) -> tuple[float, ...]:
    """The six values of a rigid transform (inverse of :func:`frame_transform`):
    R = RotX(a) RotY(b) RotZ(c); at b = +-pi/2 c is taken as zero."""
    r = t[:3, :3]
    b = math.asin(float(np.clip(r[0, 2], -1.0, 1.0)))
    if abs(r[0, 2]) < 1.0 - 1e-12:
        a, c = math.atan2(-r[1, 2], r[2, 2]), math.atan2(-r[0, 1], r[0, 0])
    else:  # gimbal lock: only a +- c is defined
        a, c = math.atan2(r[2, 1], r[1, 1]), 0.0
    return (*(float(v) for v in t[:3, 3]), a, b, c)


def _along_z(frame: Array, ref: Array, axis: Array, point: Array
             ) -> tuple[float, float, float, float, Array]:
    """From ``frame`` (z on the current axis, origin on it): theta and d that turn and slide it
    so x is the common normal to the next axis (``axis`` through ``point``), then alpha and a
    that reach that axis. ``ref``: the model's frame of the current body, which picks the
    common normal where it is not unique and the sign of x."""
    rot, origin = frame[:3, :3], frame[:3, 3]
    u, r = rot.T @ axis, rot.T @ (point - origin)
    u = u / np.linalg.norm(u)
    ez = np.array([0.0, 0.0, 1.0])
    normal = np.cross(ez, u)
    sin = float(np.linalg.norm(normal))
    ref_x = rot.T @ ref[:3, 0]
    ref_x[2] = 0.0
    if sin > PARALLEL_TOL:
        # closest points of the lines t ez and r + s u
        b, d, e = u[2], -r[2], -u @ r
        height = (b * e - d) / (1.0 - b * b)
        foot = r + (e - b * d) / (1.0 - b * b) * u
        gap = foot - height * ez
        gap[2] = 0.0
    else:  # parallel: the common normal through the body's own origin
        height = float((rot.T @ (ref[:3, 3] - origin))[2])
        gap = np.array([r[0], r[1], 0.0])
    length = float(np.linalg.norm(gap))
    if length > INTERSECT_TOL_M:
        x = gap / length
    elif sin > PARALLEL_TOL:
        x = normal / sin
    else:  # coincident axes: keep the body's x (or the frame's, if it has none across z)
        x = ref_x / np.linalg.norm(ref_x) if np.linalg.norm(ref_x) > 1e-9 else np.array(
            [1.0, 0.0, 0.0])
    if x @ ref_x < 0.0:
        x = -x
    theta = math.atan2(x[1], x[0])
    alpha = math.atan2(float(normal @ x), float(u[2]))
    a = float(gap @ x)
    turned = frame @ elementary("rz", np.array([theta]))[0] @ elementary("tz", np.array([height]))[0]
    nxt = turned @ elementary("rx", np.array([alpha]))[0] @ elementary("tx", np.array([a]))[0]
    return theta, float(height), alpha, a, nxt


def mdh_from_axes(axes: Array, points: Array, bodies: Array, flange: Array
                  ) -> tuple[tuple[float, ...], tuple[tuple[float, ...], ...], tuple[float, ...]]:
    """(base, links, flange) of the MD-H(+beta) table whose forward kinematics at q = 0 has
    joint i turning about ``axes[i]`` (n, 3) through ``points[i]`` (n, 3), world frame, and
    puts the flange at ``flange`` (4, 4). ``bodies`` (n, 4, 4): the frame of the body each
    joint moves (it only breaks ties: where the common normal runs, which way x points)."""
    axes, points = np.asarray(axes, float), np.asarray(points, float)
    bodies, flange = np.asarray(bodies, float), np.asarray(flange, float)
    n = len(axes)
    if axes.shape != (n, 3) or points.shape != (n, 3) or bodies.shape != (n, 4, 4) or n < 1:
        raise ConfigError("mdh_from_axes needs (n, 3) axes and points and (n, 4, 4) bodies")
    # the base acts like a joint about the world z axis: its rz and tz play theta and d
    theta0, d0, alpha, a, frame = _along_z(np.eye(4), np.eye(4), axes[0], points[0])
    base = (0.0, 0.0, d0, 0.0, 0.0, theta0)
    links = []
    for i in range(n):
        if i + 1 < n:
            theta, d, alpha_next, a_next, nxt = _along_z(frame, bodies[i], axes[i + 1],
                                                         points[i + 1])
        else:  # last joint: x and origin as the body's, the rest is the flange's frame
            theta, d, alpha_next, a_next, nxt = _along_z(frame, bodies[i], axes[i],
                                                         points[i])
        links.append((alpha, a, theta, d, 0.0))
        if i + 1 == n:
            last = frame @ elementary("rz", np.array([theta]))[0] @ elementary(
                "tz", np.array([d]))[0]
            return base, tuple(links), frame_params(np.linalg.inv(last) @ flange)
        alpha, a, frame = alpha_next, a_next, nxt
    raise AssertionError("unreachable")
