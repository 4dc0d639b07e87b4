"""The Panda's geometric error model in product-of-exponentials (screw) form (seed 001), as a
second calibration model beside the MD-H(+beta) chain of :mod:`serpar.kinematics.mdh`.

    T(q) = exp(b) * prod_i exp(xi_i' q_i) * M * exp(t),    xi_i' = Ad(F_i exp(e_i)) z

- ``F_i``: joint i's frame at the zero configuration (z on the joint axis, origin on it), from
  the nominal MD-H table; ``z = (0, 0, 1, 0, 0, 0)`` is the unit twist about a frame's z axis;
- ``e_i`` (6 per joint, in joint i's own frame): the error of joint i's twist, as a small
  rigid displacement of its screw axis. Why not the additive 6-vector error of Okamura &
  Park (:func:`serpar.kinematics.poe.error_jacobian`): that one also moves the twist's magnitude (a
  joint gain) and pitch (a helical joint), which a revolute joint does not have but which
  the data would identify anyway, fitting two noise parameters per joint. A displaced axis
  stays a unit, zero-pitch twist; its rotation about and translation along itself (``rz``,
  ``tz``) leave the twist unchanged, so those two are non-functional by construction;
- ``b`` (base, world frame) and ``t`` (tool, in the tool frame; its origin is the measured
  point) complete the model. Joint-zero offsets and link lengths have no parameter of their
  own: a zero offset of joint i is the same rotation of every distal twist and of M, which is
  why the POE model is complete and continuous (no parallel-axis singularity needing beta).

Parameters are named and laid out like :class:`serpar.kinematics.mdh.Chain`'s (``base.tx``,
``j3.ry``, ``tool.tz``; translation then rotation), and :func:`poe_kinematics` returns the
tool frame and the exact Jacobians in :func:`serpar.kinematics.mdh.pose_jacobian`'s convention, so the
calibration pipeline (:mod:`serpar.calibration.arm_error_models`) serves both forms.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.mdh import FRAME_PARAMS, elementary
from serpar.kinematics.poe import adjoint, exp_twist, se3_left_jacobian, skew
from serpar.kinematics.robot import PANDA, Robot, frame_transform

Array = NDArray[np.float64]

GAUGE = ("base held at nominal (a base error is one rigid motion of every joint twist and of "
         "M: the twists are expressed in the measurement frame); each joint's rz, tz move its "
         "axis along itself and are non-functional")
"""How the POE model's redundancy is resolved, in words for the report."""
_TWIST_ORDER = np.array([3, 4, 5, 0, 1, 2])
"""Parameter order (tx, ty, tz, rx, ry, rz) -> twist order (w, v) and back (an involution)."""
_Z_TWIST = np.array([0.0, 0.0, 1.0, 0.0, 0.0, 0.0])


@dataclass(frozen=True, eq=False)
class PoeChain:
    """The POE error model of a revolute chain: zero-configuration joint frames, home pose M
    (tool frame at q = 0) and the parameter names/kinds (errors only: nominal is all zero)."""

    joint_frames: Array
    """(n, 4, 4) frame of each joint at q = 0, base coordinates; the joint turns about its z."""
    home: Array
    """(4, 4) tool frame at q = 0."""

    def __post_init__(self) -> None:
        f = np.asarray(self.joint_frames, float)
        if f.ndim != 3 or f.shape[1:] != (4, 4) or f.shape[0] < 1:
            raise ConfigError(f"PoeChain.joint_frames must be (n, 4, 4), got {f.shape}")
        if np.asarray(self.home).shape != (4, 4):
            raise ConfigError(f"PoeChain.home must be 4x4, got {np.asarray(self.home).shape}")
        for name, t in (("joint_frames", f), ("home", np.asarray(self.home, float)[None])):
            rot = t[:, :3, :3]
            if not np.all(np.isfinite(t)) or np.abs(
                    rot @ rot.transpose(0, 2, 1) - np.eye(3)).max() > 1e-9:
                raise ConfigError(f"PoeChain.{name}: not finite rigid transforms")
        object.__setattr__(self, "joint_frames", f)
        object.__setattr__(self, "home", np.asarray(self.home, float))

    @property
    def n_joints(self) -> int:
        return int(self.joint_frames.shape[0])

    @property
    def names(self) -> tuple[str, ...]:
        groups = ["base"] + [f"j{i + 1}" for i in range(self.n_joints)] + ["tool"]
        return tuple(f"{g}.{p}" for g in groups for p in FRAME_PARAMS)

    @property
    def kinds(self) -> tuple[str, ...]:
        return FRAME_PARAMS * (self.n_joints + 2)

    @property
    def size(self) -> int:
        return 6 * (self.n_joints + 2)

    @property
    def nominal(self) -> tuple[float, ...]:
        return (0.0,) * self.size

    def values(self, delta: Sequence[float] | Array | None = None) -> Array:
        """The error vector itself (nominal is zero), validated like ``Chain.values``."""
        if delta is None:
            return np.zeros(self.size)
        d = np.asarray(delta, float).reshape(-1)
        if d.shape != (self.size,):
            raise ConfigError(f"parameter errors must have {self.size} entries, got {d.size}")
        return d.copy()

    def tool_shift(self, values: Array) -> Array:
        """Where the tool error puts the tool point in the nominal tool frame [m] (for a chain
        built with a zero ``tool_offset``: the tool point in the flange frame)."""
        return exp_twist(np.asarray(values, float)[-6:][_TWIST_ORDER], 1.0)[:3, 3]


def robot_poe_chain(robot: Robot, tool_offset: Sequence[float] = (0.0, 0.0, 0.0)) -> PoeChain:
    """A robot's MD-H(+beta) table (:class:`serpar.kinematics.robot.Robot`) in POE form, tool point
    ``tool_offset`` [m] in the flange frame (the same nominal kinematics as ``robot.chain``)."""
    tool = np.asarray(tool_offset, float).reshape(-1)
    if tool.shape != (3,) or not np.all(np.isfinite(tool)):
        raise ConfigError(f"tool_offset must be 3 finite numbers [m], got {tool_offset!r}")
    frame = frame_transform(robot.base)
    frames = []
    for alpha, a, theta, d, beta in robot.links:
        # RotX(alpha) TransX(a) [RotZ(theta + q)] TransZ(d): RotZ and TransZ commute with the
        # joint rotation, so the frame after them has its z on the axis and its origin on it
        for kind, v in (("rx", alpha), ("tx", a), ("rz", theta), ("tz", d)):
            frame = frame @ elementary(kind, np.array([v]))[0]
        frames.append(frame)
        frame = frame @ elementary("ry", np.array([beta]))[0]
    home = frame @ frame_transform(robot.flange)
    home[:3, 3] += home[:3, :3] @ tool
    return PoeChain(np.array(frames), home)


def panda_poe_chain(tool_offset: Sequence[float] = (0.0, 0.0, 0.0)) -> PoeChain:
    """The Panda (:mod:`serpar.kinematics.panda`'s MD-H table) in POE form, tool point
    ``tool_offset`` [m] in the flange frame (the same nominal kinematics as
    :func:`serpar.kinematics.mdh.panda_chain`)."""
    return robot_poe_chain(PANDA, tool_offset)


@dataclass(frozen=True)
class PoeKinematics:
    """Tool frames and their exact derivatives, rows ``[d position; d rotation (world)]``."""

    tool: Array
    """(N, 4, 4)"""
    jacobian: Array | None
    """(N, 6, E) with respect to the error parameters (None when not asked for)."""
    joint_jacobian: Array
    """(N, 6, n) with respect to the (link-side) joint angles."""


def poe_kinematics(chain: PoeChain, values: Array, q: Array, params: bool = True
                   ) -> PoeKinematics:
    """Forward kinematics and error Jacobian at parameter errors ``values`` for q (N, n);
    ``params=False`` skips the parameter Jacobian (inverse kinematics needs only the joints').

    Spatial error twists dT T^-1 per parameter (derivation in the module docstring's terms):
    base ``J(b)``; joint i ``(Ad(A_{i-1}) - Ad(A_i)) Ad(F_i) J(e_i)`` with A_i the product up
    to joint i, since displacing the axis by zeta turns exp(xi q) into
    exp(zeta) exp(xi q) exp(-zeta); tool ``Ad(T) J(-t)``; joint angle i ``Ad(A_{i-1}) xi_i'``.
    J is the SE(3) left Jacobian (:func:`serpar.kinematics.poe.se3_left_jacobian`), so the Jacobian is
    exact at any parameter value, not only at nominal.
    """
    q = np.atleast_2d(np.asarray(q, float))
    n = chain.n_joints
    if q.ndim != 2 or q.shape[1] != n:
        raise ConfigError(f"joint angles must have shape (N, {n}), got {q.shape}")
    errors = chain.values(values).reshape(n + 2, 6)[:, _TWIST_ORDER]   # base, joints, tool
    moved = exp_twist(errors, 1.0)
    frames = chain.joint_frames @ moved[1:-1]
    twists = adjoint(frames) @ _Z_TWIST                                # (n, 6) xi_i'
    n_pose = q.shape[0]
    prefix = np.broadcast_to(moved[0], (n_pose, 4, 4))
    ad_prev = adjoint(prefix)
    if params:
        left = se3_left_jacobian(errors * np.array([1.0] * (n + 1) + [-1.0])[:, None])
        lifted = adjoint(chain.joint_frames) @ left[1:-1]              # (n, 6, 6)
        twist_cols = [np.broadcast_to(left[0], (n_pose, 6, 6))]
    joint_cols = []
    for i in range(n):
        joint_cols.append(ad_prev @ twists[i])
        prefix = prefix @ exp_twist(twists[i], q[:, i])
        ad_next = adjoint(prefix)
        if params:
            twist_cols.append((ad_prev - ad_next) @ lifted[i])
        ad_prev = ad_next
    pose = prefix @ chain.home @ moved[-1]
    point = pose[:, :3, 3]
    jac = None
    if params:
        twist_cols.append(adjoint(pose) @ left[-1])
        jac = _point_rows(np.concatenate([c[:, :, _TWIST_ORDER] for c in twist_cols], axis=2),
                          point)
    return PoeKinematics(pose, jac, _point_rows(np.stack(joint_cols, axis=2), point))


def _point_rows(twists: Array, point: Array) -> Array:
    """Spatial twist columns (N, 6, k) -> [velocity of ``point``; angular velocity]."""
    lin = twists[:, 3:] - skew(point) @ twists[:, :3]
    return np.concatenate([lin, twists[:, :3]], axis=1)


def poe_forward(chain: PoeChain, values: Array, q: Array) -> Array:
    """(N, 4, 4) tool frames."""
    return poe_kinematics(chain, values, q, params=False).tool
