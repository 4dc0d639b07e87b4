"""A Stewart calibration campaign in the simulated cell (seed 000 §4.2 and §5.1): command the
platform through a pose set with the model in use, let the leg servos settle, and measure
each pose the way the real test bench does, with motion capture (true pose + noise).

Only the measuring device reads the simulator; the identification sees the commanded
strokes and the measured poses (:class:`identify.stewart_identification.StewartMeasurements`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from controllers.rotations import so3_exp
from controllers.stewart_kinematics import StewartGeometry, check_pose, require_pose
from controllers.stewart_servo import platform_pose
from identify.stewart_identification import StewartIdentification, StewartMeasurements, identify_lm
from sim import names
from sim.errors import ConfigError
from sim.scene import SceneConfig, build_scene
from tasks.arm_checks import controller_config
from tasks.cell_runtime import CellRuntime
from tasks.stewart_correction import PlateCommander, transform

SETTLE_S = 0.4
"""Hold at each pose before measuring: the leg PIDs settle to ~1 um."""
CAMPAIGN_SPEED = 0.15
"""Peak platform speed between poses [m/s]: only the resting poses are measured."""
N_POSES, REACH_M, TILT_DEG = 60, 0.04, 5.0
"""Default pose set: with 0.05 mm / 0.02 deg mocap noise and Table 5 errors it leaves ~0.05 mm
of error on 25 mm moves about home (0.30 mm uncalibrated); +-15 mm, +-2 deg leaves 0.3 mm."""


@dataclass(frozen=True)
class MocapNoise:
    """Motion-capture measurement noise (issue 6 defaults: 0.05 mm, 0.02 deg, 1 sigma)."""

    position_m: float = 5e-5
    angle_deg: float = 0.02

    def __post_init__(self) -> None:
        if not (0 <= self.position_m <= 1e-3 and 0 <= self.angle_deg <= 1.0):
            raise ConfigError(f"mocap noise {self.position_m} m, {self.angle_deg} deg: valid 0..1 mm, 0..1 deg")


def random_poses(n: int, seed: int, geometry: StewartGeometry, reach_m: float = REACH_M,
                 tilt_deg: float = TILT_DEG) -> tuple[np.ndarray, np.ndarray]:
    """`n` reachable poses drawn uniformly within +-reach_m and +-tilt_deg about home (poses
    outside the strokes or hinge limits are redrawn)."""
    if not 1 <= n <= 10000:
        raise ConfigError(f"poses={n}: valid 1..10000")
    rng = np.random.default_rng(seed)
    home = np.asarray(geometry.home_pos, float)
    pos, rot = [], []
    for _ in range(100 * n):
        p = home + rng.uniform(-reach_m, reach_m, 3)
        r = so3_exp(np.radians(rng.uniform(-tilt_deg, tilt_deg, 3)))
        if not check_pose(geometry, p, r):
            pos.append(p)
            rot.append(r)
            if len(pos) == n:
                return np.array(pos), np.array(rot)
    raise ConfigError(f"fewer than {n} reachable poses within +-{reach_m * 1e3:g} mm, +-{tilt_deg:g} deg")


def measure(scene_cfg: SceneConfig, pos: np.ndarray, rot: np.ndarray, believed: np.ndarray | None = None,
            noise: MocapNoise = MocapNoise(), seed: int = 0) -> StewartMeasurements:
    """Drive the simulated platform (with its hidden errors) through the poses using the model
    with `believed` errors (None = nominal); returns commanded strokes and mocap poses."""
    return measure_with_truth(scene_cfg, pos, rot, believed, noise, seed)[0]


def measure_with_truth(scene_cfg: SceneConfig, pos: np.ndarray, rot: np.ndarray,
                       believed: np.ndarray | None = None, noise: MocapNoise = MocapNoise(),
                       seed: int = 0) -> tuple[StewartMeasurements, np.ndarray, np.ndarray]:
    """:func:`measure`, and the simulator's true poses (pos (N, 3), rot (N, 3, 3)) for scoring."""
    scene = build_scene(dataclasses.replace(scene_cfg, n_conductors=0))
    rt = CellRuntime.create(scene, controller_config(noise=False), seed=seed)
    plate = PlateCommander.create(scene.model, scene.data, scene_cfg.stewart, believed)
    rt.observers.append(lambda r: plate.update(r.scene.data, r.time))
    rng = np.random.default_rng(seed + 7919)
    strokes, tpos, trot = [], [], []
    for p, r in zip(pos, rot):
        require_pose(plate.geometry, p, r)
        goal = transform(r, p)
        rt.run(plate.move_to(scene.data, goal, rt.time, CAMPAIGN_SPEED) + SETTLE_S)
        true_pos, true_rot = platform_pose(scene.model, scene.data, names.STEWART)
        strokes.append(plate.strokes(goal))
        tpos.append(true_pos)
        trot.append(true_rot)
    return mocap(np.array(strokes), np.array(tpos), np.array(trot), noise, rng), np.array(tpos), np.array(trot)


def mocap(strokes: np.ndarray, true_pos: np.ndarray, true_rot: np.ndarray, noise: MocapNoise,
          rng: np.random.Generator) -> StewartMeasurements:
    """What motion capture reports of the true poses: each pose with independent noise."""
    mpos, mrot = [], []
    for p, r in zip(true_pos, true_rot):  # per pose, position then angle (the draw order is kept)
        mpos.append(p + noise.position_m * rng.standard_normal(3))
        mrot.append(so3_exp(np.radians(noise.angle_deg) * rng.standard_normal(3)) @ r)
    return StewartMeasurements(strokes, np.array(mpos), np.array(mrot))


def calibrate(scene_cfg: SceneConfig, n_poses: int = N_POSES, noise: MocapNoise = MocapNoise(),
              seed: int = 0) -> StewartIdentification:
    """Measure `n_poses` random poses with the nominal model and identify the 42 errors."""
    pos, rot = random_poses(n_poses, seed, scene_cfg.stewart.geometry())
    meas = measure(scene_cfg, pos, rot, None, noise, seed)
    return identify_lm(scene_cfg.stewart.geometry(), meas)
