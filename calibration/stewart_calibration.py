"""`serpar calibrate stewart` (issue 6, seed 000 §4.2-4.3): hidden geometric errors in the
platform, a measurement campaign through its nominal model, identification by each solver,
compensation, and the campaign repeated through the identified model.

Measurements come from one of three sources, and only the measuring device sees the truth:
'cell', the MuJoCo cell (leg servos, closed loops, the plate on top) measured by simulated motion
capture (:mod:`serpar.calibration.stewart_campaign`); 'stereo', the same cell measured by the top stereo pair
from rendered pixels (:mod:`serpar.calibration.stewart_stereo`); or 'kinematic', the built geometry's exact
kinematics with motion capture (fast, for studies). Errors before and after are scored against
the simulator's true pose at the training poses (as the seed does) and at separate random
verification poses: in the Stewart base frame for motion capture, in the frame registered at
home for the cameras (the frame the cell uses them in; see :mod:`serpar.calibration.stewart_stereo`).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from serpar.calibration.stewart_campaign import (
    CampaignResult,
    MocapNoise,
    measure_with_truth,
    mocap,
    random_poses,
)
from serpar.calibration.stewart_identification import (
    StewartIdentification,
    StewartMeasurements,
    identify_lm,
)
from serpar.calibration.stewart_params import load_stewart_parameters
from serpar.calibration.stewart_poses import (
    optimal_poses,
    predicted_error_rms,
    reachable,
    smallest_singular_value,
    table3_poses,
)
from serpar.calibration.stewart_solvers import SwarmConfig, identify_pso, identify_tls
from serpar.calibration.stewart_stereo import (
    StereoConfig,
    planning_view,
    regauge,
    stereo_campaign,
    top_pair,
    visible_random_poses,
)
from serpar.errors import ConfigError, IdentificationError
from serpar.kinematics.stewart_kinematics import (
    StewartGeometry,
    forward_kinematics,
    inverse_kinematics,
)
from serpar.kinematics.stewart_table import table5_errors
from serpar.sim.scene import SceneConfig
from serpar.sim.stewart import MAX_JOINT_ERROR, StewartConfig, built_geometry

SOLVERS = ("tls", "lm", "pso")
SOURCES = ("cell", "kinematic", "stereo")
POSE_SETS = ("table3", "optimal", "random")
SEED000_BOX = (5e-3, np.radians(0.5))
"""Seed 000's simulated set-up: initial platform errors within +-5 mm and +-0.5 deg."""

Poses = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class StewartCalibrationConfig:
    poses: str = "table3"
    n_poses: int = 20
    """Pose count for 'optimal' and 'random' (Table 3 has 20)."""
    noise: MocapNoise = field(default_factory=MocapNoise)
    solvers: tuple[str, ...] = SOLVERS
    errors: str = "seed000"
    """'seed000': drawn uniformly and scaled (to first order) so the initial errors at the training poses reach
    seed 000's +-5 mm / +-0.5 deg box; 'table5': seed 000 Table 5; or a parameters file."""
    source: str = "cell"
    """'cell' (motion capture in the MuJoCo cell), 'stereo' (the top cameras in the cell; `noise`
    is then unused: the cameras' error is measured) or 'kinematic'."""
    stereo: StereoConfig = field(default_factory=StereoConfig)
    verify_poses: int = 30
    swarm: SwarmConfig = field(default_factory=SwarmConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.poses not in POSE_SETS:
            raise ConfigError(f"--poses {self.poses!r}; valid: {', '.join(POSE_SETS)} or a count")
        if not 7 <= self.n_poses <= 500 or not 1 <= self.verify_poses <= 500:
            raise ConfigError(f"poses {self.n_poses} (valid 7..500), verify poses {self.verify_poses} (valid 1..500)")
        bad = [s for s in self.solvers if s not in SOLVERS]
        if bad or not self.solvers:
            raise ConfigError(f"--solver {','.join(bad) or '(none)'}; valid: {', '.join(SOLVERS)}, all")
        if self.source not in SOURCES:
            raise ConfigError(f"--source {self.source!r}; valid: {', '.join(SOURCES)}")


@dataclass(frozen=True)
class PoseErrors:
    """Platform errors (true minus commanded) at a pose set: position [m], rotation [rad]."""

    position: np.ndarray
    rotation: np.ndarray

    @property
    def max_abs(self) -> np.ndarray:
        """(6,) largest |error| per axis: x, y, z [m], then about x, y, z [rad]."""
        return np.concatenate([np.abs(self.position).max(0), np.abs(self.rotation).max(0)])

    @property
    def u_bar(self) -> float:
        """Seed 002 Eq. 29 U-bar: the mean over x, y, z of the mean |error| [m]."""
        return float(np.mean(np.abs(self.position)))

    @property
    def e_bar(self) -> float:
        """Seed 002 Eq. 29 E-bar: the mean distance error [m]."""
        return float(np.mean(np.linalg.norm(self.position, axis=1)))

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(np.sum(self.position**2, axis=1))))

    @property
    def rms_angle(self) -> float:
        """RMS of the rotation error's angle [rad]."""
        return float(np.sqrt(np.mean(np.sum(self.rotation**2, axis=1))))


@dataclass(frozen=True)
class SolverOutcome:
    solver: str
    seconds: float
    identification: StewartIdentification | None = None
    train: PoseErrors | None = None
    verify: PoseErrors | None = None
    parameter_error_max_m: float = float("nan")
    failure: str | None = None
    """Why the solver gave no model (e.g. TLS diverging under noise); None when it did."""
    unreachable: tuple[int, ...] = ()
    """Stereo: training/verification poses the identified model could not reach (not scored)."""


@dataclass(frozen=True)
class StewartCalibrationReport:
    hidden: np.ndarray
    train_poses: Poses
    before_train: PoseErrors
    before_verify: PoseErrors
    outcomes: list[SolverOutcome]
    predicted_rms_m: float
    """RMS position error the noise alone should leave at the verification poses."""
    smallest_singular_value: float
    source: str = "cell"
    noise_used: tuple[float, float] = (0.0, 0.0)
    """Per-axis 1-sigma pose noise [m, rad] the prediction uses: the configured motion-capture
    noise, or the stereo pair's measured error."""
    campaign: CampaignResult | None = None
    """The training campaign: measured vs true poses, skipped poses (stereo)."""
    planned_poses: int = 0
    """Poses in the planned set (the training poses are those of them measured)."""


def training_poses(cfg: StewartCalibrationConfig, geometry: StewartGeometry,
                   scene_cfg: SceneConfig | None = None) -> Poses:
    """The planned pose set. For the stereo source, random and optimal sets are drawn among poses
    the top pair sees (planned from the cell drawing); Table 3 is taken as it is and its poses
    out of view are skipped, reported, by the campaign."""
    if cfg.source == "stereo" and cfg.poses != "table3":
        visible = planning_view(cfg.stereo, scene_cfg or SceneConfig())
        if cfg.poses == "random":
            return visible_random_poses(cfg.n_poses, cfg.seed, geometry, visible)
        return optimal_poses(geometry, cfg.n_poses, visible_random_poses(20 * cfg.n_poses, cfg.seed + 3, geometry,
                                                                         visible), cfg.seed)
    if cfg.poses == "table3":
        pos, rot = table3_poses()
        problems = reachable(geometry, pos, rot)
        if problems:
            raise ConfigError("Table 3 poses outside the platform's limits: " + "; ".join(problems))
        return pos, rot
    if cfg.poses == "random":
        return random_poses(cfg.n_poses, cfg.seed, geometry)
    return optimal_poses(geometry, cfg.n_poses, random_poses(20 * cfg.n_poses, cfg.seed + 3, geometry), cfg.seed)


def pose_errors(true_pos: np.ndarray, true_rot: np.ndarray, pos: np.ndarray, rot: np.ndarray) -> PoseErrors:
    rotvec = Rotation.from_matrix(np.einsum("nij,nkj->nik", true_rot, rot)).as_rotvec()
    return PoseErrors(true_pos - pos, rotvec)


def _scored(result: CampaignResult, poses: Poses) -> PoseErrors:
    """Errors at the poses the campaign reached (a scoring campaign skips only unreachable ones)."""
    ok = np.all(np.isfinite(result.true_pos), axis=1)
    return pose_errors(result.true_pos[ok], result.true_rot[ok], poses[0][ok], poses[1][ok])


def hidden_errors(cfg: StewartCalibrationConfig, stewart: StewartConfig, train: Poses) -> np.ndarray:
    if cfg.errors == "table5":
        return table5_errors()
    if cfg.errors != "seed000":
        return load_stewart_parameters(cfg.errors)
    draw = np.random.default_rng(cfg.seed).uniform(-1.0, 1.0, (6, 7))
    _, unit_pos, unit_rot = _kinematic_truth(stewart, 1e-3 * draw, train, None)
    errs = pose_errors(unit_pos, unit_rot, *train).max_abs
    scale = 1e-3 / max(errs[:3].max() / SEED000_BOX[0], errs[3:].max() / SEED000_BOX[1])
    if scale * np.abs(draw).max() > MAX_JOINT_ERROR:
        raise ConfigError(f"seed000 errors would need {scale * 1e3:.2f} mm per parameter; limit "
                          f"{MAX_JOINT_ERROR * 1e3:g} mm")
    return scale * draw


def _kinematic_truth(stewart: StewartConfig, hidden: np.ndarray, poses: Poses,
                     believed: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The strokes the model with `believed` errors commands for `poses`, and where the platform
    built with `hidden` errors then stands: (strokes, true pos, true rot)."""
    model, model_dl = built_geometry(dataclasses.replace(stewart, joint_errors=believed))
    built, dl = built_geometry(dataclasses.replace(stewart, joint_errors=hidden))
    strokes = inverse_kinematics(model, *poses) - model_dl
    out = [forward_kinematics(built, s + dl, p, r)[:2] for s, p, r in zip(strokes, *poses)]
    return strokes, np.array([o[0] for o in out]), np.array([o[1] for o in out])


Measure = Callable[[Poses, np.ndarray | None, int, bool], CampaignResult]


def measurer(cfg: StewartCalibrationConfig, scene_cfg: SceneConfig, hidden: np.ndarray) -> Measure:
    """The campaign: (poses, believed errors, seed, measure) -> CampaignResult; `measure` False
    (the re-measurements and verification poses) scores the truth only, without noise."""
    cell = dataclasses.replace(scene_cfg, stewart=dataclasses.replace(scene_cfg.stewart, joint_errors=hidden))
    if cfg.source == "stereo":
        pair = top_pair(cfg.stereo)
        return lambda poses, believed, seed, measure: stereo_campaign(cell, *poses, believed, cfg.stereo,
                                                                      pair, seed, measure)

    def mocap_campaign(poses: Poses, believed: np.ndarray | None, seed: int, measure: bool) -> CampaignResult:
        noise = cfg.noise if measure else MocapNoise(0.0, 0.0)
        if cfg.source == "cell":
            meas, true_pos, true_rot = measure_with_truth(cell, *poses, believed, noise, seed)
        else:
            strokes, true_pos, true_rot = _kinematic_truth(scene_cfg.stewart, hidden, poses, believed)
            meas = mocap(strokes, true_pos, true_rot, noise, np.random.default_rng(seed + 7919))
        return CampaignResult(meas if measure else None, true_pos, true_rot, np.arange(len(true_pos)))

    return mocap_campaign


def measured_noise(campaign: CampaignResult) -> tuple[float, float]:
    """Per-axis RMS of the measured-minus-true poses: position [m], angle [rad]."""
    if campaign.meas is None or not len(campaign.kept):
        return float("nan"), float("nan")
    return (float(np.sqrt(np.mean(campaign.position_error**2))), float(np.sqrt(np.mean(campaign.angle_error**2))))


def solve(name: str, geometry: StewartGeometry, meas: StewartMeasurements, swarm: SwarmConfig) -> StewartIdentification:
    if name == "lm":
        return identify_lm(geometry, meas)
    if name == "tls":
        return identify_tls(geometry, meas)
    return identify_pso(geometry, meas, swarm)


def run_calibration(cfg: StewartCalibrationConfig, scene_cfg: SceneConfig | None = None,
                    on_stage: Callable[[str], None] | None = None) -> StewartCalibrationReport:
    stage = on_stage or (lambda _: None)
    scene_cfg = scene_cfg or SceneConfig()
    geometry = scene_cfg.stewart.geometry()
    train = training_poses(cfg, geometry, scene_cfg)
    verify = random_poses(cfg.verify_poses, cfg.seed + 1, geometry)
    hidden = hidden_errors(cfg, scene_cfg.stewart, train)
    campaign = measurer(cfg, scene_cfg, hidden)
    planned = len(train[0])
    stage(f"measuring the training poses through the nominal model ({cfg.source})")
    first = campaign(train, None, cfg.seed, True)
    train = (train[0][first.kept], train[1][first.kept])  # the poses measured (stereo may skip some)
    if first.meas is None:
        raise ConfigError(f"the {cfg.source} campaign measured nothing")
    meas = first.meas
    before_train = pose_errors(first.true_pos[first.kept], first.true_rot[first.kept], *train)
    stage("measuring the verification poses through the nominal model")
    verified = campaign(verify, None, cfg.seed + 1, False)
    outcomes = []
    for name in cfg.solvers:
        stage(f"identifying with {name}")
        t0 = time.perf_counter()
        try:
            ident = solve(name, geometry, meas, cfg.swarm)
        except IdentificationError as exc:
            outcomes.append(SolverOutcome(name, time.perf_counter() - t0, failure=str(exc)))
            continue
        seconds = time.perf_counter() - t0
        if cfg.source == "stereo":  # the frame closest to the design (see regauge)
            ident = dataclasses.replace(ident, errors=regauge(ident.errors, geometry))
        stage(f"re-measuring through the {name}-identified model")
        after = campaign(train, ident.errors, cfg.seed, False)
        after_v = campaign(verify, ident.errors, cfg.seed + 1, False)
        outcomes.append(SolverOutcome(name, seconds, ident, _scored(after, train), _scored(after_v, verify),
                                      float(np.abs(ident.errors - hidden).max()),
                                      unreachable=tuple(k for k, _ in after.skipped + after_v.skipped)))
    sigma = measured_noise(first) if cfg.source == "stereo" else (cfg.noise.position_m, np.radians(cfg.noise.angle_deg))
    predicted = predicted_error_rms(geometry, train, verify, *sigma)
    return StewartCalibrationReport(hidden, train, before_train, _scored(verified, verify), outcomes,
                                    predicted, smallest_singular_value(geometry, *train), cfg.source, sigma, first,
                                    planned)
