"""Test scenes for the vision of steps 1 and 2, and the ground truth to score them against.

A scene is the cell with the Stewart platform driven (servo + simulation) to a pose near home
and some conductors taken from the tray and seated in chosen holes. The seating is
*kinematic*: the conductor's free joint is set so its shoulder sits on the hole's entry
centre with its axis along the hole axis, then ``mj_forward``. This is a test-scene
construction (a picture of a cell with some parts already inserted), not the task's
insertion, which happens by physics. The platform moves first and the conductors are seated
after it, so no further stepping is needed (stepping would only let seated parts settle on
the support contacts).

The ``truth_*`` readers take simulator sites and are for scoring only; the vision code never
calls them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.controllers.stewart_servo import StewartServo
from serpar.errors import ConfigError
from serpar.kinematics.rotations import euler_to_rot
from serpar.kinematics.stewart_kinematics import check_pose
from serpar.sim import names
from serpar.sim.scene import Scene, SceneConfig, build_scene
from serpar.vision.plate import PlateMeasurement
from serpar.vision.tray_conductors import ConductorSighting

RAMP_S = 0.2
"""Minimum-jerk ramp from home to the test pose [s]."""
SETTLE_S = 0.6
"""Hold after the ramp [s]: the leg PID's integral unwinds to ~0.2 um (checks/stewart_checks.py)."""


@dataclass(frozen=True)
class PlatformOffset:
    """A platform pose relative to home, in the Stewart base frame: position [m], fixed-axis
    roll/pitch/yaw (eps, phi, theta) [rad] as in :func:`serpar.kinematics.rotations.euler_to_rot`."""

    dpos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    euler: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def pose(self, cfg: SceneConfig) -> tuple[np.ndarray, np.ndarray]:
        """(pos, rot) of the platform frame in the Stewart base frame."""
        return cfg.stewart.home_pos + np.asarray(self.dpos), euler_to_rot(*self.euler)


def random_offset(cfg: SceneConfig, rng: np.random.Generator, max_shift: float = 5e-3,
                  max_angle_deg: float = 2.0) -> PlatformOffset:
    """A reachable pose drawn uniformly within +-max_shift [m] and +-max_angle_deg per axis."""
    geom = cfg.stewart.geometry()
    for _ in range(1000):
        d = [float(v) for v in rng.uniform(-max_shift, max_shift, 3)]
        e = [float(v) for v in np.radians(rng.uniform(-max_angle_deg, max_angle_deg, 3))]
        off = PlatformOffset((d[0], d[1], d[2]), (e[0], e[1], e[2]))
        if not check_pose(geom, *off.pose(cfg)):
            return off
    raise ConfigError(f"no reachable pose within {max_shift} m / {max_angle_deg} deg of home")


def move_platform(scene: Scene, offset: PlatformOffset, ramp_s: float = RAMP_S,
                  settle_s: float = SETTLE_S) -> None:
    """Drive the legs (StewartServo) from the current pose to `offset` along a minimum-jerk
    ramp, then hold for settle_s; the arm is gravity-held every step."""
    m, d = scene.model, scene.data
    servo = StewartServo.from_model(m, scene.config.stewart.geometry(), names.STEWART)
    mujoco.mj_forward(m, d)
    pos0, rot0 = servo.platform_pose(d)
    start = np.r_[pos0, _euler_of(rot0)]
    goal_pos, goal_rot = offset.pose(scene.config)
    goal = np.r_[goal_pos, offset.euler]
    n_ramp = max(1, round(ramp_s / m.opt.timestep))
    n_settle = round(settle_s / m.opt.timestep)
    for k in range(1, n_ramp + n_settle + 1):
        tau = min(1.0, k / n_ramp)
        x = start + (goal - start) * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
        if k <= n_ramp:
            servo.command_pose(d, x[:3], euler_to_rot(*x[3:]))
        else:
            servo.command_pose(d, goal_pos, goal_rot)
        scene.gravity_hold_arm()
        mujoco.mj_step(m, d)
    mujoco.mj_forward(m, d)


def _euler_of(rot: np.ndarray) -> np.ndarray:
    """(eps, phi, theta) of R = Rz(theta) Ry(phi) Rx(eps)."""
    return np.array([np.arctan2(rot[2, 1], rot[2, 2]), -np.arcsin(np.clip(rot[2, 0], -1, 1)),
                     np.arctan2(rot[1, 0], rot[0, 0])])


def seat_conductor(scene: Scene, conductor: int, hole: int) -> None:
    """Kinematically seat `conductor`: shoulder on the entry centre of `hole`, axis along the
    hole axis (test-scene construction, not an insertion); then mj_forward."""
    m, d = scene.model, scene.data
    if not 0 <= conductor < len(scene.conductor_bodies):
        raise ConfigError(f"conductor {conductor}: valid 0..{len(scene.conductor_bodies) - 1}")
    if not 0 <= hole < len(scene.hole_sites):
        raise ConfigError(f"hole {hole}: valid 0..{len(scene.hole_sites) - 1}")
    mujoco.mj_kinematics(m, d)
    site = scene.hole_sites[hole]
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, d.site_xmat[site])
    joint = m.body_jntadr[scene.conductor_bodies[conductor]]
    adr, dof = m.jnt_qposadr[joint], m.jnt_dofadr[joint]
    d.qpos[adr:adr + 3] = d.site_xpos[site]
    d.qpos[adr + 3:adr + 7] = quat
    d.qvel[dof:dof + 6] = 0.0
    mujoco.mj_forward(m, d)


def make_scene(cfg: SceneConfig | None = None, offset: PlatformOffset | None = None,
               seated: Mapping[int, int] | None = None) -> Scene:
    """Build the cell, move the platform to `offset` (if any), then seat conductor -> hole
    for every item of `seated`."""
    scene = build_scene(cfg or SceneConfig())
    if offset is not None:
        move_platform(scene, offset)
    used = set()
    for conductor, hole in (seated or {}).items():
        if hole in used:
            raise ConfigError(f"hole {hole} given to two conductors")
        used.add(hole)
        seat_conductor(scene, conductor, hole)
    return scene


def truth_holes(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Scoring only: entry centres (n, 3) and unit axes out of the holes (n, 3), base frame."""
    d = scene.data
    return (d.site_xpos[scene.hole_sites].copy(),
            d.site_xmat[scene.hole_sites].reshape(-1, 3, 3)[:, :, 2].copy())


def truth_conductor_tops(scene: Scene, conductors: list[int] | None = None) -> np.ndarray:
    """Scoring only: the `conductor{k}/top` sites (n, 3) of `conductors` (default: all)."""
    m, d = scene.model, scene.data
    ks = range(len(scene.conductor_bodies)) if conductors is None else conductors
    return np.array([d.site_xpos[m.site(f"{names.conductor(k)}top").id] for k in ks])


def truth_occupancy(scene: Scene, tol: float = 5e-4) -> np.ndarray:
    """Scoring only: for each hole, whether a conductor's shoulder sits within `tol` of its entry."""
    m, d = scene.model, scene.data
    holes, _ = truth_holes(scene)
    shoulders = np.array([d.site_xpos[m.site(f"{names.conductor(k)}shoulder").id]
                          for k in range(len(scene.conductor_bodies))]).reshape(-1, 3)
    if len(shoulders) == 0:
        return np.zeros(len(holes), bool)
    dist = np.linalg.norm(holes[:, None, :] - shoulders[None, :, :], axis=2)
    return dist.min(axis=1) < tol


@dataclass(frozen=True)
class PlateScore:
    """Measured holes against the truth [m, deg]; centre errors over the seen holes."""

    mean: float
    p95: float
    max: float
    lateral_p95: float
    """p95 of the error across the hole axis (what a misaligned insertion feels)."""
    axis_deg: float
    occupancy_correct: float
    """Fraction of seen holes whose empty/occupied status is right."""
    seen: int


@dataclass(frozen=True)
class HoleErrors:
    """Per seen hole [m]: centre error, its part across the hole axis, the hole's own raw
    triangulation error (holes that have one), and whether its empty/occupied status is right."""

    centre: np.ndarray
    lateral: np.ndarray
    raw: np.ndarray
    status_right: np.ndarray
    axis_deg: float


def hole_errors(scene: Scene, measurement: PlateMeasurement) -> HoleErrors:
    """Scoring only: every seen hole of a plate measurement against the hole sites."""
    centres, axes = truth_holes(scene)
    occupied = truth_occupancy(scene)
    seen = [h for h in measurement.holes if h.status != "unseen"]
    err = np.array([h.centre - centres[h.index] for h in seen]).reshape(-1, 3)
    along = err @ axes[0]
    lateral = np.linalg.norm(err - np.outer(along, axes[0]), axis=1)
    raw = np.array([np.linalg.norm(h.raw - centres[h.index]) for h in seen if h.raw is not None])
    right = np.array([(h.status == "occupied") == occupied[h.index] for h in seen], bool)
    angle = float(np.degrees(np.arccos(np.clip(measurement.normal @ axes[0], -1.0, 1.0))))
    return HoleErrors(np.linalg.norm(err, axis=1), lateral, raw, right, angle)


def score_plate(scene: Scene, measurement: PlateMeasurement) -> PlateScore:
    """Scoring only: a plate measurement against the hole sites, summarised."""
    e = hole_errors(scene, measurement)
    return PlateScore(float(e.centre.mean()), float(np.percentile(e.centre, 95)), float(e.centre.max()),
                      float(np.percentile(e.lateral, 95)), e.axis_deg, float(e.status_right.mean()),
                      len(e.centre))


def tray_match(scene: Scene, sightings: Sequence[ConductorSighting], in_tray: Sequence[int],
               tol: float = 1e-3) -> tuple[np.ndarray, int, int]:
    """Scoring only: for the conductors `in_tray`, the distance of each found top to its nearest
    sighting (those within `tol`), how many were missed, and how many sightings match none."""
    tops = truth_conductor_tops(scene, list(in_tray))
    seen = np.array([s.top for s in sightings]).reshape(-1, 3)
    if len(seen) == 0:
        return np.zeros(0), len(tops), 0
    dist = np.linalg.norm(tops[:, None] - seen[None], axis=2)
    nearest = dist.min(axis=1)
    return nearest[nearest < tol], int((nearest >= tol).sum()), int((dist.min(axis=0) >= tol).sum())


@dataclass(frozen=True)
class TrayScore:
    mean: float
    p95: float
    max: float
    found: int
    expected: int
    pockets_correct: float


def score_tray(scene: Scene, sightings: Sequence[ConductorSighting]) -> TrayScore:
    """Scoring only: sightings against the tops of the conductors still in the tray (each
    sighting is matched to the nearest true top; its pocket must be that part's pocket)."""
    m, d = scene.model, scene.data
    pockets = np.array([d.site_xpos[m.site(f"{names.TRAY}pocket{k}").id]
                        for k in range(scene.config.tray.n_pockets)])
    tops = truth_conductor_tops(scene)
    in_tray = np.flatnonzero(np.min(np.linalg.norm(tops[:, None, :2] - pockets[None, :, :2], axis=2),
                                    axis=1) < 1e-3)
    measured = np.array([s.top for s in sightings]).reshape(-1, 3)
    dist = np.linalg.norm(measured[:, None] - tops[None, in_tray], axis=2)
    nearest = in_tray[dist.argmin(axis=1)]
    err = dist.min(axis=1)
    home = np.linalg.norm(tops[nearest, None, :2] - pockets[None, :, :2], axis=2).argmin(axis=1)
    ok = np.mean([s.pocket == int(p) for s, p in zip(sightings, home)])
    return TrayScore(float(err.mean()), float(np.percentile(err, 95)), float(err.max()),
                     len(sightings), len(in_tray), float(ok))
