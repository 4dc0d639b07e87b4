"""An arm from its URDF/MJCF file as the dynamics diagnosis and its twins use it
(:class:`~serpar.sim.rigid_arm.ArmModel`): the file's own masses, inertias, armature, damping
and joint limits are the nominal model; its chain of hinge joints from the base to the flange
(serpar.sim.robot_file) are the arm's joints, in order."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np

from serpar.sim.rigid_arm import ArmModel
from serpar.sim.robot_dynamics import dynamics_model, dynamics_spec

FRICTION_SHARE = 0.25
"""Largest joint friction searched, as a share of the joint's torque limit (per rad/s for the
viscous term): a drive that lost more than a quarter of its torque to friction could not move
its arm. (The TX40's heaviest: 7 N m Coulomb, 8 N m s/rad viscous on a 132 N m axis.)"""
PANDA_FRICTION_BOUNDS = (10.0, 5.0)
"""Where the file states no torque limits: a Panda-class drive's bounds."""


@lru_cache(maxsize=8)
def arm_from_file(path: str) -> ArmModel:
    """The arm of a URDF/MJCF file (ConfigError, one line, for a file that is not one; every
    repair reading it took is in the arm's ``notes``)."""
    robot = dynamics_model(path)
    m, joints = robot.model, list(robot.joints)
    limited = np.asarray(m.jnt_limited[joints], bool)
    rng = np.asarray(m.jnt_range[joints], float)
    q_min = np.where(limited, rng[:, 0], -np.pi)
    q_max = np.where(limited, rng[:, 1], np.pi)
    effort = np.abs(np.asarray(m.jnt_actfrcrange[joints], float)).max(axis=1)
    has_effort = np.asarray(m.jnt_actfrclimited[joints], bool) & (effort > 0)
    bounds = PANDA_FRICTION_BOUNDS
    if has_effort.any():
        top = FRICTION_SHARE * float(effort[has_effort].max())
        bounds = (max(bounds[0], top), max(bounds[1], top))
    flange = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, robot.flange_body)
    return ArmModel(robot.name, str(path), lambda: dynamics_spec(path)[0], robot.joint_names,
                    robot.link_bodies, flange, tuple(float(x) for x in robot.flange_pose[:3, 3]),
                    tuple(map(float, q_min)), tuple(map(float, q_max)),
                    notes=tuple(f"reading {Path(path).name}: {r}" for r in robot.repairs),
                    friction_bounds=bounds)
