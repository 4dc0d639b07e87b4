"""MD-H (+beta) kinematics of a serial arm as a chain of elementary motions, with its exact
error Jacobian (seed 003 §3.3, §4.1).

Each geometric parameter of seed 003's five-parameter link model
``RotX(alpha) TransX(a) RotZ(theta + q) TransZ(d) RotY(beta)``, of the base frame and of the
tool frame is one rotation about, or one translation along, an axis of the frame it acts in.
Why that form: the derivative of the tool pose with respect to any parameter is then the
screw of that axis (``u x (p - o)`` and ``u`` for a rotation, ``u`` for a translation),
exactly and at any parameter value, so the error Jacobian needs neither finite differences
nor a small-error linearisation, and the same code serves the identification and the
parameter-redundancy analysis.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.panda import FLANGE_D, MDH_A, MDH_ALPHA, MDH_D, N_JOINTS

KINDS = ("rx", "ry", "rz", "tx", "ty", "tz")
"""Elementary motions: rotation about / translation along the x, y or z axis."""
LINK_PARAMS = ("alpha", "a", "theta", "d", "beta")
"""Seed 003 Eq. 3 order; theta carries the joint angle."""
_LINK_KINDS = ("rx", "tx", "rz", "tz", "ry")
FRAME_PARAMS = ("tx", "ty", "tz", "rx", "ry", "rz")
"""Base and tool frames: translation, then X-Y-Z rotations."""


@dataclass(frozen=True)
class Chain:
    """A serial chain of elementary motions; ``joint[e] >= 0`` adds that joint's angle."""

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    nominal: tuple[float, ...]
    joint: tuple[int, ...]
    n_joints: int

    def __post_init__(self) -> None:
        n = len(self.names)
        if not (len(self.kinds) == len(self.nominal) == len(self.joint) == n):
            raise ConfigError("chain names, kinds, nominal and joint must have the same length")
        bad = sorted(set(self.kinds) - set(KINDS))
        if bad:
            raise ConfigError(f"unknown elementary motion(s) {bad}; valid: {', '.join(KINDS)}")
        if len(set(self.names)) != n:
            raise ConfigError("chain parameter names must be unique")
        carried = sorted(j for j in self.joint if j >= 0)
        if carried != list(range(self.n_joints)):
            raise ConfigError(f"each of the {self.n_joints} joints must drive exactly one element")
        for j, k in zip(self.joint, self.kinds):
            if j >= 0 and k[0] != "r":
                raise ConfigError("joints here are revolute: a joint must drive a rotation")
        if not np.all(np.isfinite(self.nominal)):
            raise ConfigError("chain nominal values must be finite")

    @property
    def size(self) -> int:
        return len(self.names)

    @property
    def joint_elements(self) -> NDArray[np.int64]:
        """Element index driven by each joint, joint order."""
        idx = np.asarray(self.joint)
        return np.array([int(np.flatnonzero(idx == j)[0]) for j in range(self.n_joints)])

    def values(self, delta: Sequence[float] | NDArray[np.float64] | None = None
               ) -> NDArray[np.float64]:
        """Nominal values plus a parameter error vector (zero when None)."""
        v = np.asarray(self.nominal, float)
        if delta is None:
            return v.copy()
        d = np.asarray(delta, float).reshape(-1)
        if d.shape != v.shape:
            raise ConfigError(f"parameter errors must have {v.size} entries, got {d.size}")
        return v + d


def panda_chain(tool_offset: Sequence[float] = (0.0, 0.0, 0.0)) -> Chain:
    """The Panda's MD-H(+beta) chain from :mod:`serpar.sim.arm`: base frame (6), five parameters per
    joint (35), tool frame (6) whose origin is ``tool_offset`` [m] in the flange frame."""
    tool = np.asarray(tool_offset, float).reshape(-1)
    if tool.shape != (3,) or not np.all(np.isfinite(tool)):
        raise ConfigError(f"tool_offset must be 3 finite numbers [m], got {tool_offset!r}")
    names: list[str] = []
    kinds: list[str] = []
    nominal: list[float] = []
    joint: list[int] = []

    def add(name: str, kind: str, value: float, j: int = -1) -> None:
        names.append(name)
        kinds.append(kind)
        nominal.append(float(value))
        joint.append(j)

    for p in FRAME_PARAMS:
        add(f"base.{p}", p, 0.0)
    for i in range(N_JOINTS):
        table = {"alpha": MDH_ALPHA[i], "a": MDH_A[i], "theta": 0.0, "d": MDH_D[i], "beta": 0.0}
        for p, kind in zip(LINK_PARAMS, _LINK_KINDS):
            add(f"j{i + 1}.{p}", kind, table[p], i if p == "theta" else -1)
    flange_tool = (tool[0], tool[1], FLANGE_D + tool[2], 0.0, 0.0, 0.0)
    for p, value in zip(FRAME_PARAMS, flange_tool):
        add(f"tool.{p}", p, value)
    return Chain(tuple(names), tuple(kinds), tuple(nominal), tuple(joint), N_JOINTS)


def elementary(kind: str, v: NDArray[np.float64]) -> NDArray[np.float64]:
    """(N, 4, 4) homogeneous transforms of one elementary motion by the values ``v`` (N,)."""
    v = np.asarray(v, float)
    t = np.tile(np.eye(4), (v.size, 1, 1))
    axis = "xyz".index(kind[1])
    if kind[0] == "t":
        t[:, axis, 3] = v
        return t
    i, j = (axis + 1) % 3, (axis + 2) % 3
    c, s = np.cos(v), np.sin(v)
    t[:, i, i] = c
    t[:, j, j] = c
    t[:, i, j] = -s
    t[:, j, i] = s
    return t


@dataclass(frozen=True)
class ChainFrames:
    """Per element, the world axis it moves along/about and the origin the rotation acts at."""

    axes: NDArray[np.float64]
    """(N, E, 3) unit axis of each element in the base (world) frame."""
    origins: NDArray[np.float64]
    """(N, E, 3) origin of the frame each element acts in."""
    tool: NDArray[np.float64]
    """(N, 4, 4) tool frame."""


def chain_frames(chain: Chain, values: NDArray[np.float64], q: NDArray[np.float64]
                 ) -> ChainFrames:
    """Forward kinematics of ``chain`` at element ``values`` (E,) for joint angles q (N, n)."""
    q = _joint_array(chain, q)
    values = np.asarray(values, float).reshape(-1)
    if values.size != chain.size:
        raise ConfigError(f"chain values must have {chain.size} entries, got {values.size}")
    n = q.shape[0]
    pose = np.tile(np.eye(4), (n, 1, 1))
    axes = np.empty((n, chain.size, 3))
    origins = np.empty((n, chain.size, 3))
    for e, (kind, j) in enumerate(zip(chain.kinds, chain.joint)):
        v = np.full(n, values[e]) + (q[:, j] if j >= 0 else 0.0)
        pose = pose @ elementary(kind, v)
        # a rotation leaves its own axis fixed and a translation leaves the frame's axes fixed,
        # so the frame after the element gives the element's world axis in both cases
        axes[:, e] = pose[:, :3, "xyz".index(kind[1])]
        origins[:, e] = pose[:, :3, 3]
    return ChainFrames(axes, origins, pose)


def forward(chain: Chain, values: NDArray[np.float64], q: NDArray[np.float64]
            ) -> NDArray[np.float64]:
    """(N, 4, 4) tool frames."""
    return chain_frames(chain, values, q).tool


def pose_jacobian(chain: Chain, frames: ChainFrames) -> NDArray[np.float64]:
    """(N, 6, E) derivative of the tool pose, [d position; d rotation (world axis-angle)],
    with respect to each element's value (for a joint element also its joint angle)."""
    rotation = np.array([k[0] == "r" for k in chain.kinds])
    p = frames.tool[:, None, :3, 3]
    lin = np.where(rotation[None, :, None], np.cross(frames.axes, p - frames.origins),
                   frames.axes)
    ang = np.where(rotation[None, :, None], frames.axes, 0.0)
    return np.concatenate([lin, ang], axis=2).transpose(0, 2, 1)


def _joint_array(chain: Chain, q: NDArray[np.float64]) -> NDArray[np.float64]:
    q = np.atleast_2d(np.asarray(q, float))
    if q.ndim != 2 or q.shape[1] != chain.n_joints:
        raise ConfigError(f"joint angles must have shape (N, {chain.n_joints}), got {q.shape}")
    return q
