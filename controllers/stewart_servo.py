"""Pose commands for the Stewart platform's six leg servos.

The leg actuators ``leg1..6`` are MuJoCo PID position servos on the slide joints (see
``serpar.sim.stewart.build_stewart_spec``): ``data.ctrl`` is the commanded stroke [m]. A pose is the
platform frame (site ``platform_centre``, the centre of the spherical-joint plane) in the
Stewart base frame (body ``base``: universal-joint centres at z = 0). In the cell the base
sits at ``SceneConfig.stewart_base`` in the world; in the standalone model at the origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError, LimitError
from serpar.kinematics.rotations import quat_to_rot
from serpar.kinematics.stewart_kinematics import (
    HINGE_DEFINITIONS,
    N_LEGS,
    HingeDefinition,
    StewartGeometry,
    require_pose,
)
from serpar.sim.physics import wake_tree_of

GEOMETRY_MATCH_TOL = 1e-9
"""Model joint sites must equal the geometry's to this [m]: commands assume the same robot."""


def _id(model: mujoco.MjModel, kind: mujoco.mjtObj, name: str) -> int:
    k = mujoco.mj_name2id(model, kind, name)
    if k < 0:
        raise ConfigError(f"{name!r} not in the model; check the prefix (scene: 'stewart/')")
    return k


def as_rotation(rot_or_quat: np.ndarray) -> np.ndarray:
    """3x3 rotation from a rotation matrix or a quaternion (w, x, y, z)."""
    a = np.asarray(rot_or_quat, dtype=float)
    if a.shape == (4,):
        return quat_to_rot(a)
    if a.shape == (3, 3):
        return a
    raise ConfigError(f"orientation must be a 3x3 matrix or a (w, x, y, z) quaternion, got {a.shape}")


@dataclass(frozen=True)
class StewartServo:
    """Inverse kinematics + limit check in front of the leg servos of one model."""

    geometry: StewartGeometry
    actuator_ids: tuple[int, ...]
    """Ids of leg1..leg6 (in leg order) in the model."""
    platform_site: int
    """Id of the site ``platform_centre``."""
    base_body: int
    """Id of the body ``base`` (the Stewart base frame)."""
    hinge_definition: HingeDefinition = "deflection"
    platform_dof: int = -1
    """First dof of the platform's free joint: nudged to wake the sleeping platform (-1: the
    model has sleeping off or the servo was built by hand; nothing to wake)."""

    def __post_init__(self) -> None:
        if len(self.actuator_ids) != N_LEGS:
            raise ConfigError(f"need {N_LEGS} leg actuators, got {len(self.actuator_ids)}")
        if self.hinge_definition not in HINGE_DEFINITIONS:
            raise ConfigError(f"hinge definition {self.hinge_definition!r}; valid: "
                              f"{', '.join(HINGE_DEFINITIONS)}")

    @classmethod
    def from_model(cls, model: mujoco.MjModel, geometry: StewartGeometry, prefix: str = "",
                   hinge_definition: HingeDefinition = "deflection",
                   match_tol: float = GEOMETRY_MATCH_TOL) -> StewartServo:
        """Look the ids up once (prefix "stewart/" in the cell, "" standalone).

        Raises ConfigError if the model's joint sites differ from the geometry by more than
        `match_tol` [m] or its stroke differs: the IK would then command another robot. A
        platform built with hidden joint errors is commanded through its (nominal or
        calibrated) model with `match_tol` set to the errors' bound.
        """
        acts = tuple(_id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"{prefix}leg{i}")
                     for i in range(1, N_LEGS + 1))
        site = _id(model, mujoco.mjtObj.mjOBJ_SITE, prefix + "platform_centre")
        base = _id(model, mujoco.mjtObj.mjOBJ_BODY, prefix + "base")
        joints = np.array([model.site_pos[_id(model, mujoco.mjtObj.mjOBJ_SITE,
                                              f"{prefix}p_joint{i}")]
                           for i in range(1, N_LEGS + 1)]) - model.site_pos[site]
        if np.max(np.abs(joints - geometry.P)) > match_tol:
            raise ConfigError("model platform joints differ from the geometry's P by "
                              f"{np.max(np.abs(joints - geometry.P)):.3g} m")
        hi = float(model.actuator_ctrlrange[acts[0], 1])
        if abs(hi - geometry.stroke) > GEOMETRY_MATCH_TOL:
            raise ConfigError(f"model leg ctrlrange [0, {hi}] m differs from the geometry's "
                              f"stroke {geometry.stroke} m")
        dof = int(model.body_dofadr[model.site_bodyid[site]])
        return cls(geometry, acts, site, base, hinge_definition, dof)

    def command_strokes(self, data: mujoco.MjData, strokes: np.ndarray) -> None:
        """Write six stroke commands [m]; LimitError names any leg outside [0, stroke]."""
        s = np.asarray(strokes, dtype=float)
        if s.shape != (N_LEGS,) or not np.all(np.isfinite(s)):
            raise ConfigError(f"strokes must be {N_LEGS} finite numbers [m], got {s}")
        bad = [f"leg {i + 1} stroke {v * 1e3:.3f} mm outside [0, {self.geometry.stroke * 1e3:g}] mm"
               for i, v in enumerate(s) if not 0.0 <= v <= self.geometry.stroke]
        if bad:
            raise LimitError("; ".join(bad))
        self._write(data, s)

    def command_pose(self, data: mujoco.MjData, pos: np.ndarray,
                     rot_or_quat: np.ndarray) -> np.ndarray:
        """Command the platform pose in the Stewart base frame; returns the strokes [m].

        Raises LimitError (naming leg, limit and range) before writing anything if the pose
        violates a stroke or hinge limit.
        """
        strokes = require_pose(self.geometry, np.asarray(pos, dtype=float),
                               as_rotation(rot_or_quat), self.hinge_definition)
        self._write(data, strokes)
        return strokes

    def _write(self, data: mujoco.MjData, strokes: np.ndarray) -> None:
        ids = list(self.actuator_ids)
        if self.platform_dof >= 0 and np.any(data.ctrl[ids] != strokes):
            wake_tree_of(data, self.platform_dof)
        data.ctrl[ids] = strokes

    def platform_pose(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Simulated pose (pos [m], rot) of site platform_centre in the Stewart base frame.

        Needs data.site_xpos / xmat up to date (after mj_step or mj_forward).
        """
        return relative_pose(data.xpos[self.base_body], data.xmat[self.base_body],
                             data.site_xpos[self.platform_site], data.site_xmat[self.platform_site])


def relative_pose(base_pos: np.ndarray, base_mat: np.ndarray, pos: np.ndarray,
                  mat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose (pos, mat as 9 or 3x3 world values) expressed in the frame (base_pos, base_mat)."""
    rb = np.asarray(base_mat, dtype=float).reshape(3, 3)
    return rb.T @ (np.asarray(pos, dtype=float) - base_pos), rb.T @ np.reshape(mat, (3, 3))


def platform_pose(model: mujoco.MjModel, data: mujoco.MjData,
                  prefix: str = "") -> tuple[np.ndarray, np.ndarray]:
    """Simulated platform pose in the Stewart base frame, looking the ids up by name."""
    site = _id(model, mujoco.mjtObj.mjOBJ_SITE, prefix + "platform_centre")
    base = _id(model, mujoco.mjtObj.mjOBJ_BODY, prefix + "base")
    return relative_pose(data.xpos[base], data.xmat[base], data.site_xpos[site],
                         data.site_xmat[site])
