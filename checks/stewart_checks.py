"""Stewart kinematics and pose-command measurements (issue 3): IK/FK round trip, and
commanded vs simulated platform pose in the standalone MuJoCo model."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from serpar.checks.workspace import WorkspaceBox, pose_rotations, sample_poses
from serpar.controllers.stewart_servo import StewartServo
from serpar.errors import ConfigError
from serpar.kinematics.rotations import euler_to_rot, rotation_angle
from serpar.kinematics.stewart_kinematics import (
    LIMIT_NAMES,
    HingeDefinition,
    StewartGeometry,
    forward_kinematics,
    inverse_kinematics,
    limit_violations,
)
from serpar.sim.physics import PhysicsConfig
from serpar.sim.stewart import StewartConfig, build_stewart_spec, loop_site_ids, loop_violation


@dataclass(frozen=True)
class RoundTripResult:
    """IK -> FK over valid random poses; errors of the recovered pose against the drawn one."""

    poses: int
    max_position_error_m: float
    max_rotation_error_rad: float
    max_stroke_residual_m: float
    max_iterations: int
    mean_iterations: float

    def as_dict(self) -> dict[str, object]:
        return asdict(self)


def valid_poses(geom: StewartGeometry, n: int, seed: int = 0,
                definition: HingeDefinition = "deflection", box: WorkspaceBox | None = None,
                ) -> tuple[np.ndarray, np.ndarray]:
    """n poses drawn uniformly in the box (default: the seed's) that pass every limit:
    (pos (n, 3), rot (n, 3, 3))."""
    box = box or WorkspaceBox()
    rng = np.random.default_rng(seed)
    got_pos, got_rot, have = [], [], 0
    for _ in range(1000):  # ~20 % pass: a few rounds suffice; the cap stops an empty region
        pos, euler = sample_poses(max(4 * n, 1000), rng, box)
        rot = pose_rotations(euler)
        v = limit_violations(geom, pos, rot, definition)
        ok = ~np.any([v[k].any(axis=-1) for k in LIMIT_NAMES], axis=0)
        got_pos.append(pos[ok])
        got_rot.append(rot[ok])
        have += int(ok.sum())
        if have >= n:
            return np.concatenate(got_pos)[:n], np.concatenate(got_rot)[:n]
    raise ConfigError(f"only {have} of {n} valid poses found: is the box inside the workspace?")


def ik_fk_round_trip(geom: StewartGeometry, n: int = 1000, seed: int = 0,
                     definition: HingeDefinition = "deflection") -> RoundTripResult:
    """Strokes from IK, pose back from FK (guess: home), compared with the drawn pose."""
    pos, rot = valid_poses(geom, n, seed, definition)
    strokes = inverse_kinematics(geom, pos, rot)
    perr, rerr, res, iters = [], [], [], []
    for k in range(n):
        p, r, it = forward_kinematics(geom, strokes[k])
        perr.append(np.linalg.norm(p - pos[k]))
        rerr.append(float(rotation_angle(r, rot[k])))
        res.append(np.max(np.abs(inverse_kinematics(geom, p, r) - strokes[k])))
        iters.append(it)
    return RoundTripResult(n, float(max(perr)), float(max(rerr)), float(max(res)),
                           int(max(iters)), float(np.mean(iters)))


TRACKING_POSES_MM_DEG: tuple[tuple[float, ...], ...] = (
    # X, Y, Z [mm], eps, phi, theta [deg]: spread over the reachable part of the seed's box.
    (40.0, -30.0, 255.0, 2.0, -1.0, 4.0),
    (-45.0, 20.0, 268.0, -3.0, 2.0, -6.0),
    (20.0, 55.0, 250.0, 1.0, 3.0, 8.0),
    (-30.0, -45.0, 270.0, -2.0, -3.0, -3.0),
    (60.0, 10.0, 262.0, 3.0, 1.0, 2.0),
)


@dataclass(frozen=True)
class TrackingResult:
    """Commanded vs simulated pose of site platform_centre after each ramp + settle, and at
    `early_s` into the settle (to show the integral tail)."""

    poses: int
    ramp_s: float
    settle_s: float
    timestep_s: float
    position_error_m: tuple[float, ...]
    rotation_error_deg: tuple[float, ...]
    early_s: float
    early_position_error_m: tuple[float, ...]
    early_rotation_error_deg: tuple[float, ...]
    max_loop_violation_m: float

    @property
    def max_position_error_m(self) -> float:
        return max(self.position_error_m)

    @property
    def max_rotation_error_deg(self) -> float:
        return max(self.rotation_error_deg)

    def as_dict(self) -> dict[str, object]:
        return asdict(self) | {"max_position_error_m": self.max_position_error_m,
                               "max_rotation_error_deg": self.max_rotation_error_deg}


def _pose_of(row: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    return np.array(row[:3]) * 1e-3, np.radians(row[3:])


def _errors(servo: StewartServo, model: mujoco.MjModel, data: mujoco.MjData,
            goal_pos: np.ndarray, goal_rot: np.ndarray) -> tuple[float, float]:
    mujoco.mj_forward(model, data)  # site poses of the current state, not of the last step
    pos, rot = servo.platform_pose(data)
    return (float(np.linalg.norm(pos - goal_pos)),
            float(np.degrees(rotation_angle(rot, goal_rot))))


def commanded_vs_simulated(poses: tuple[tuple[float, ...], ...] = TRACKING_POSES_MM_DEG,
                           ramp_s: float = 0.3, settle_s: float = 0.6, early_s: float = 0.3,
                           cfg: StewartConfig | None = None,
                           physics: PhysicsConfig | None = None) -> TrackingResult:
    """Drive the standalone model through `poses` (mm, deg) via StewartServo.command_pose.

    From home, each move blends (X, Y, Z, eps, phi, theta) along a minimum-jerk profile over
    ramp_s, re-running IK every step, then holds for settle_s; the simulated pose is then
    compared with the commanded one. Perfect geometry: the model is built from cfg.

    Why 0.6 s of settling: the leg PID damps on the measured velocity (one position input),
    so during a move it lags kv v / kp and its integral winds up to the imax clamp (300 N,
    i.e. 190 um of leg overshoot). That unwinds with the integral time constant kp / ki =
    80 ms (measured 72 ms): ~14 um and 1.6e-3 deg are left 0.3 s after a 0.3 s ramp,
    ~0.2 um and 2e-5 deg after 0.6 s. Raising ki (Routh margin) or a slower ramp do not help.
    """
    cfg, physics = cfg or StewartConfig(), physics or PhysicsConfig()
    if ramp_s < 0 or settle_s <= 0 or not 0 < early_s <= settle_s:
        raise ConfigError(f"ramp_s={ramp_s}, settle_s={settle_s}, early_s={early_s}: "
                          "need ramp >= 0, 0 < early <= settle")
    spec = build_stewart_spec(cfg, physics)
    physics.apply(spec)
    model = spec.compile()
    data = mujoco.MjData(model)
    servo = StewartServo.from_model(model, cfg.geometry())
    sites = loop_site_ids(model)
    dt = model.opt.timestep
    start = np.r_[cfg.home_pos, 0.0, 0.0, 0.0]
    servo.command_pose(data, start[:3], np.eye(3))
    mujoco.mj_forward(model, data)
    final, early, loop = [], [], 0.0
    n_ramp, n_early, n_settle = (round(t / dt) for t in (ramp_s, early_s, settle_s))
    for row in poses:
        goal_pos, goal_euler = _pose_of(row)
        goal = np.r_[goal_pos, goal_euler]
        for k in range(1, n_ramp + 1):
            tau = k / n_ramp
            x = start + (goal - start) * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
            servo.command_pose(data, x[:3], euler_to_rot(*x[3:]))
            mujoco.mj_step(model, data)
            loop = max(loop, loop_violation(model, data, site_ids=sites))
        goal_rot = euler_to_rot(*goal_euler)
        servo.command_pose(data, goal_pos, goal_rot)
        for k in range(1, n_settle + 1):
            mujoco.mj_step(model, data)
            if k == n_early:
                early.append(_errors(servo, model, data, goal_pos, goal_rot))
        final.append(_errors(servo, model, data, goal_pos, goal_rot))
        loop = max(loop, loop_violation(model, data, site_ids=sites))
        start = goal
    return TrackingResult(len(poses), ramp_s, settle_s, dt, tuple(e[0] for e in final),
                          tuple(e[1] for e in final), early_s, tuple(e[0] for e in early),
                          tuple(e[1] for e in early), loop)
