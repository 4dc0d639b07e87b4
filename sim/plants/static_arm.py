"""The simulated "real" arm of a geometric calibration campaign for any arm read from its model
file (``--robot FILE``): MuJoCo's kinematics of the edited model, never the calibration's own
formula.

Like the Panda's campaign (:mod:`serpar.sim.plants.static_panda`), every body on the path from
the base to the flange is moved by hidden errors drawn per seed (the first one by the base
registration's, the others by link errors, in pos and quat; a rotated body rotates its joint's
axis), a laser-tracker target (SMR) is added at the nominal tool offset from the flange plus
its own error, and the tracker sees its centre with noise. The same error magnitudes as the
Panda's (:class:`serpar.sim.plants.static_panda.TruthConfig`'s defaults). Geometric only: the
joints are rigid and gravity plays no part (a robot file's masses are seldom the arm's), so the
campaign shows what the kinematic calibration recovers, not a gravity-aware model.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.mdh import forward
from serpar.kinematics.robot import Robot
from serpar.sim.arm_measurements import PositionSet
from serpar.sim.plants.static_panda import Campaign, TruthConfig
from serpar.sim.robot_file import compile_spec, load_robot_model, read_chain, robot_spec

TOOL_SITE = "smr"
_PANDA = TruthConfig()


@dataclass(frozen=True)
class GeometricCampaignConfig:
    """The hidden errors and the measurement campaign (150 + 100 poses, as the Panda's)."""

    seed: int = 3
    link_pos_sigma_m: float = _PANDA.link_pos_sigma_m
    link_rot_sigma_rad: float = _PANDA.link_rot_sigma_rad
    base_pos_sigma_m: float = _PANDA.base_pos_sigma_m
    base_rot_sigma_rad: float = _PANDA.base_rot_sigma_rad
    tool_pos_sigma_m: float = _PANDA.tool_pos_sigma_m
    tool_offset_m: tuple[float, float, float] = _PANDA.tool_offset_m
    tracker_sigma_m: float = _PANDA.tracker_sigma_m
    n_train: int = _PANDA.n_train
    n_verify: int = _PANDA.n_verify
    joint_margin_rad: float = _PANDA.joint_margin_rad
    min_tool_height_m: float = _PANDA.min_tool_height_m

    def __post_init__(self) -> None:
        for name in ("link_pos_sigma_m", "link_rot_sigma_rad", "base_pos_sigma_m",
                     "base_rot_sigma_rad", "tool_pos_sigma_m", "tracker_sigma_m",
                     "joint_margin_rad"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ConfigError(f"GeometricCampaignConfig.{name} must be >= 0, got {value!r}")
        if self.tracker_sigma_m <= 0 or self.n_train < 1 or self.n_verify < 1:
            raise ConfigError("GeometricCampaignConfig: tracker noise, n_train and n_verify "
                              "must be positive")


def _chain_bodies(robot: Robot) -> tuple[list[str], str, NDArray, NDArray]:
    """Names of the bodies from the base to the flange's, and the flange's pose in the last
    of them (position, rotation matrix)."""
    rm = load_robot_model(robot.source)
    m = rm.model
    kind, fid = rm.flange
    body = int(m.site_bodyid[fid]) if kind == "site" else fid
    pos, rot = np.zeros(3), np.eye(3)
    if kind == "site":
        pos = np.array(m.site_pos[fid])
        mujoco.mju_quat2Mat(rot.reshape(-1), m.site_quat[fid])
    path = []
    while body > 0:
        path.append(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, body))
        body = int(m.body_parentid[body])
    if any(name is None for name in path):
        raise ConfigError(f"--robot {robot.source}: every body from the base to the flange "
                          "needs a name for the simulated campaign")
    return path[::-1], path[0], pos, rot


def build_plant(robot: Robot, cfg: GeometricCampaignConfig, errors: bool = True
                ) -> tuple[mujoco.MjModel, NDArray[np.int64]]:
    """The robot file with hidden errors (seeded by cfg.seed) and the SMR site; its chain's
    qpos addresses."""
    if robot.source == "built-in":
        raise ConfigError(f"{robot.label}: the geometric campaign needs a robot file")
    spec = robot_spec(robot.source)
    names, last, fpos, frot = _chain_bodies(robot)
    rng = np.random.default_rng([cfg.seed, 3])
    on = 1.0 if errors else 0.0
    for i, name in enumerate(names):
        body = spec.body(name)
        sp, sr = ((cfg.base_pos_sigma_m, cfg.base_rot_sigma_rad) if i == 0
                  else (cfg.link_pos_sigma_m, cfg.link_rot_sigma_rad))
        quat = np.asarray(body.quat, float) / np.linalg.norm(body.quat)
        mujoco.mju_quatIntegrate(quat, on * rng.normal(size=3) * sr, 1.0)
        body.pos = np.asarray(body.pos, float) + on * rng.normal(size=3) * sp
        body.quat = quat
    tool = spec.body(last).add_site(name=TOOL_SITE)
    tool.pos = (fpos + frot @ np.asarray(cfg.tool_offset_m)
                + on * rng.normal(size=3) * cfg.tool_pos_sigma_m)
    model = compile_spec(spec, robot.source)
    return model, read_chain(model, robot.source).qpos


def tool_points(model: mujoco.MjModel, qpos: NDArray[np.int64], q: NDArray[np.float64]
                ) -> NDArray[np.float64]:
    """(N, 3) SMR centres in the world (tracker) frame at joint angles q (N, n)."""
    data = mujoco.MjData(model)
    site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, TOOL_SITE)
    out = np.empty((len(q), 3))
    for k, row in enumerate(np.atleast_2d(q)):
        data.qpos[qpos] = row
        mujoco.mj_kinematics(model, data)
        out[k] = data.site_xpos[site]
    return out


def sample_poses(robot: Robot, cfg: GeometricCampaignConfig, n: int, rng: np.random.Generator
                 ) -> NDArray[np.float64]:
    """Uniform joint angles inside the limits less a margin, nominal tool above the table."""
    lo = np.asarray(robot.q_min) + cfg.joint_margin_rad
    hi = np.asarray(robot.q_max) - cfg.joint_margin_rad
    chain = robot.chain(cfg.tool_offset_m)
    poses: list[NDArray[np.float64]] = []
    for _ in range(1000):
        q = rng.uniform(lo, hi, size=(2 * n, robot.n_joints))
        high = forward(chain, chain.values(), q)[:, 2, 3] > cfg.min_tool_height_m
        poses.extend(q[high])
        if len(poses) >= n:
            return np.asarray(poses[:n])
    raise ConfigError(f"{robot.label}: too few poses put the tool above "
                      f"{cfg.min_tool_height_m} m")


def run_geometric_campaign(robot: Robot, cfg: GeometricCampaignConfig) -> Campaign:
    """Measure the hidden plant at cfg.n_train + cfg.n_verify random poses (the Panda
    campaign's :class:`Campaign`; rigid joints, so no deflection)."""
    rng = np.random.default_rng([cfg.seed, 0])
    model, qpos = build_plant(robot, cfg)
    q = sample_poses(robot, cfg, cfg.n_train + cfg.n_verify, rng)
    truth = tool_points(model, qpos, q)
    seen = truth + rng.normal(size=truth.shape) * cfg.tracker_sigma_m
    s = cfg.n_train
    sets = [PositionSet(q[r], seen[r], cfg.tracker_sigma_m, robot=robot)
            for r in (slice(0, s), slice(s, None))]
    return Campaign(sets[0], sets[1], truth[:s], truth[s:], np.zeros_like(q))
