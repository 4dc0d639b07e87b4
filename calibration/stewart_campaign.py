"""A Stewart calibration campaign in the simulated cell (seed 000 §4.2 and §5.1): command the
platform through a pose set with the model in use, let the leg servos settle, and measure
each pose the way the real test bench does, with motion capture (true pose + noise).

Only the measuring device reads the simulator; the identification sees the commanded
strokes and the measured poses (:class:`serpar.calibration.stewart_identification.StewartMeasurements`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from serpar.calibration.stewart_identification import (
    StewartIdentification,
    StewartMeasurements,
    identify_lm,
)
from serpar.controllers.arm_controller import controller_config
from serpar.controllers.cell_runtime import CellRuntime
from serpar.controllers.plate_commander import PlateCommander, transform
from serpar.controllers.stewart_servo import platform_pose
from serpar.errors import ConfigError
from serpar.kinematics.rotations import so3_exp
from serpar.kinematics.stewart_kinematics import StewartGeometry, check_pose, require_pose
from serpar.sim import names
from serpar.sim.scene import Scene, SceneConfig, build_scene

CAMPAIGN_SPEED = 0.15
"""Peak platform speed between poses [m/s]: only the resting poses are measured."""
N_POSES, REACH_M, TILT_DEG = 60, 0.04, 5.0
"""Default pose set: with 0.05 mm / 0.02 deg mocap noise and Table 5 errors it leaves ~0.05 mm
of error on 25 mm moves about home (0.30 mm uncalibrated); +-15 mm, +-2 deg leaves 0.3 mm."""


@dataclass(frozen=True)
class SettleCriterion:
    """When a commanded pose counts as reached: the bench watches the leg encoders (the stroke
    sensors), as a real one would, instead of a fixed clock.

    The leg PIDs end a campaign move 50-180 um behind their command and close that error with
    the integral action's slow pole (time constant kp/ki = 80 ms; measured 72 ms): a fixed 0.4 s
    hold left 0.2-0.8 um on the legs and 1-3 um on the platform pose (the pose amplifies leg
    errors up to ~5x), which was the in-cell calibration's 4 um floor. Settled means every leg
    within `leg_error_m` of its command and slower than `leg_speed_m_s`, or the legs not moving
    at all (MuJoCo has put the still platform to sleep, serpar.sim.stewart.PLATFORM_SLEEP:
    nothing changes after that): 0.40-0.61 s after a Table 3 move (mean 0.51 s)."""

    leg_error_m: float = 1e-7
    """|stroke - command| on every leg [m]: up to ~0.5 um on the pose."""
    leg_speed_m_s: float = 1e-6
    """Leg speed from two encoder readings one control period apart [m/s]: the error's own
    decay rate at leg_error_m (0.1 um / 72 ms = 1.4 um/s), so both hold at once."""
    max_s: float = 2.0
    """Longest hold [s] (~25 time constants); a pose that needs more is measured as it is and
    its hold recorded at this value in :attr:`CampaignCell.settle_times`."""
    min_s: float = 0.0
    """Shortest hold [s]; min_s = max_s is a fixed hold."""

    def __post_init__(self) -> None:
        for name in ("leg_error_m", "leg_speed_m_s", "max_s"):
            if not float(getattr(self, name)) > 0:
                raise ConfigError(f"settle {name}={getattr(self, name)} must be > 0")
        if not 0 <= self.min_s <= self.max_s:
            raise ConfigError(f"settle min_s={self.min_s} must be within 0..max_s={self.max_s}")

    @classmethod
    def fixed(cls, seconds: float) -> SettleCriterion:
        """A hold of `seconds` whatever the legs do."""
        return cls(max_s=seconds, min_s=seconds)


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
    cell = CampaignCell.create(scene_cfg, believed, seed)
    rng = np.random.default_rng(seed + 7919)
    settled = [cell.settle_at(p, r) for p, r in zip(pos, rot)]
    strokes, tpos, trot = (np.array([s[i] for s in settled]) for i in range(3))
    return mocap(strokes, tpos, trot, noise, rng), tpos, trot


@dataclass
class CampaignCell:
    """The cell a campaign drives: the platform (with its hidden errors) commanded through the
    model with the `believed` errors, no conductors, the arm holding its start pose (out of the
    top cameras' view of the plate)."""

    scene: Scene
    rt: CellRuntime
    plate: PlateCommander
    settle: SettleCriterion = field(default_factory=SettleCriterion)
    settle_times: list[float] = field(default_factory=list)
    """Each hold's length [s], in order."""

    @classmethod
    def create(cls, scene_cfg: SceneConfig, believed: np.ndarray | None, seed: int,
               settle: SettleCriterion = SettleCriterion()) -> CampaignCell:
        scene = build_scene(dataclasses.replace(scene_cfg, n_conductors=0))
        rt = CellRuntime.create(scene, controller_config(noise=False), seed=seed)
        plate = PlateCommander.create(scene.model, scene.data, scene_cfg.stewart, believed)
        rt.observers.append(lambda r: plate.update(r.scene.data, r.time))
        return cls(scene, rt, plate, settle)

    def settle_at(self, pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Drive to the pose, hold until settled; (commanded strokes, true pos, true rot in the
        Stewart base frame)."""
        require_pose(self.plate.geometry, pos, rot)
        goal = transform(rot, pos)
        self.rt.run(self.plate.move_to(self.scene.data, goal, self.rt.time, CAMPAIGN_SPEED))
        self.hold()
        true_pos, true_rot = platform_pose(self.scene.model, self.scene.data, names.STEWART)
        return self.plate.strokes(goal), true_pos, true_rot

    def hold(self) -> float:
        """Run the cell until the legs meet :attr:`settle` (or its max_s); returns the hold [s]."""
        m, d, crit = self.scene.model, self.scene.data, self.settle
        acts = list(self.plate.servo.actuator_ids)
        adr = [m.sensor_adr[m.sensor(f"{names.STEWART}stroke{i + 1}").id] for i in range(len(acts))]
        before, held = d.sensordata[adr].copy(), 0.0
        while held < crit.max_s - 1e-9:
            self.rt.step()
            held += self.rt.dt
            now = d.sensordata[adr].copy()
            speed = float(np.max(np.abs(now - before))) / self.rt.dt
            error = float(np.max(np.abs(now - d.ctrl[acts])))
            settled = speed == 0.0 or (error <= crit.leg_error_m and speed <= crit.leg_speed_m_s)
            if settled and held >= crit.min_s - 1e-9:
                break
            before = now
        self.settle_times.append(held)
        return held


@dataclass(frozen=True)
class CampaignResult:
    """What one campaign gives: the measurements the identification sees, and (for scoring
    only) the simulator's true poses in the frame the measurements live in."""

    meas: StewartMeasurements | None
    """Commanded strokes and measured poses of the measured poses; None for a scoring-only run."""
    true_pos: np.ndarray
    """(N, 3) true platform positions of every pose [m]."""
    true_rot: np.ndarray
    kept: np.ndarray
    """Indices of the measured poses in the pose set (all of them, but for the stereo source)."""
    skipped: tuple[tuple[int, str], ...] = ()
    """(pose index, why) of every pose the instrument could not measure."""
    registration_error: tuple[float, float] | None = None
    """Stereo: the home registration's own error (position [m], angle [rad]), common to every
    pose (a gauge: it cancels in the identification and the scoring)."""

    @property
    def position_error(self) -> np.ndarray:
        """(kept, 3) measured minus true position [m]."""
        return np.zeros((0, 3)) if self.meas is None else self.meas.pos - self.true_pos[self.kept]

    @property
    def angle_error(self) -> np.ndarray:
        """(kept, 3) rotation vectors of the measured orientations relative to the true ones [rad]."""
        if self.meas is None:
            return np.zeros((0, 3))
        rel = np.einsum("nij,nkj->nik", self.meas.rot, self.true_rot[self.kept])
        return Rotation.from_matrix(rel).as_rotvec().reshape(-1, 3)


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
