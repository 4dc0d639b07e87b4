"""What one assembly episode is (issue 5): a frozen, validated config, the fixed outcome
taxonomy, and the success-rate interval. YAML only at the command-line edge
(`serpar.sim.config_io.load_yaml_config(EpisodeConfig, path)`, unknown keys rejected)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from serpar.errors import ConfigError
from serpar.kinematics.stewart_table import table5_errors
from serpar.sim import names
from serpar.sim.arm import PANDA_COULOMB_FRICTION
from serpar.sim.mjcf_export import read_any_model
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_changes import ArmPlantChanges
from serpar.sim.plants.drive_friction import MAX_SCALE, DriveFriction, DriveFrictionLaw
from serpar.sim.plants.from_model_file import arm_plant_changes
from serpar.sim.scene import Scene, SceneConfig
from serpar.sim.stewart import StewartConfig
from serpar.sim.tolerances import DISTRIBUTIONS

CONTROLLERS = ("force_position", "impedance")
ERROR_MODES = ("table5", "random", "none")
CALIBRATIONS = ("campaign", "none")
CAMERA_WIDTHS = (2048, 1024)
FRICTION_FORMS = ("coulomb", "gaz")
N_HOLES = 36


class Outcome(enum.Enum):
    """How one hole ended: success or exactly one failure type."""

    SUCCESS = "success"
    VISION_MISS = "vision_miss"
    GRASP_FAIL = "grasp_fail"
    ALIGN_FAIL = "align_fail"
    JAM = "jam"
    OVERFORCE = "overforce"
    TIMEOUT = "timeout"
    DROPPED = "dropped"
    SIM_FAULT = "sim_fault"
    """The simulator could not finish it (a MuJoCo warning, a blown-up state): a Monte Carlo
    trial's (serpar montecarlo); an episode's hole cycle that breaks is scored by its phase."""


@dataclass(frozen=True)
class HiddenStewartErrors:
    """Geometric errors of the simulated platform that its own model does not know."""

    mode: str = "table5"
    """'table5': seed 000's identified errors of the real cell; 'random': drawn per seed with
    Table 5's RMS per column; 'none': perfect geometry."""
    scale: float = 1.0

    def __post_init__(self) -> None:
        if self.mode not in ERROR_MODES:
            raise ConfigError(f"hidden_errors.mode {self.mode!r}; valid: {', '.join(ERROR_MODES)}")
        if not 0 <= self.scale <= 20:
            raise ConfigError(f"hidden_errors.scale {self.scale}: valid 0..20")

    def draw(self, seed: int) -> np.ndarray:
        """(6, 7) errors [m] for an episode with `seed`."""
        table = table5_errors()
        if self.mode == "none":
            return np.zeros_like(table)
        if self.mode == "table5":
            return self.scale * table
        rms = np.sqrt(np.mean(table**2, axis=0))
        return self.scale * rms * np.random.default_rng(seed).standard_normal(table.shape)


@dataclass(frozen=True)
class EpisodeConfig:
    seed: int = 0
    holes: tuple[int, ...] | int = N_HOLES
    """How many holes to fill (the empty ones vision finds, in order), or which ones."""
    controller: str = "force_position"
    stewart_correction: bool = True
    """Step 5 on; off = the serial robot alone."""
    stewart_calibration: str = "campaign"
    """The platform's model of itself in step 5: 'campaign' = identified from a simulated
    motion-capture campaign in this cell (seed 000 §4.2; run once, then cached), 'none' = the
    nominal model (uncalibrated), or the path of an identified-parameters file
    (`serpar.calibration.stewart_params`)."""
    hidden_errors: HiddenStewartErrors = field(default_factory=HiddenStewartErrors)
    arm_friction: float = 0.3
    """Dry joint friction of the simulated arm as a fraction of a real Panda's
    (:data:`serpar.sim.arm.PANDA_COULOMB_FRICTION`); the controllers do not model it. The torque loop
    around the Panda's link-side sensors removes most motor friction; 0.3 leaves the arm
    ~0.1-0.4 mm off a commanded pose, like the seed's measured Panda (Fig. 3: up to 0.4 mm, within
    0.1 mm near the goal; Fig. 5: < 0.2 mm), where the frictionless arm is 0.02 mm off. This is
    what defeats the serial robot alone. 0 = frictionless."""
    arm_friction_form: str = "coulomb"
    """How arm_friction acts: 'coulomb' = the dry level at speed as MuJoCo joint ``frictionloss``
    (a constraint: sticks at rest); 'gaz' = the whole published Panda model, a sigmoid with
    offset (sim/plants/drive_friction.py), times arm_friction, as a drive torque each step."""
    sensor_noise: bool = True
    tolerance_distribution: str = "uniform"
    camera_width: int = 2048
    damage_force_n: float = 20.0
    hole_time_limit_s: float = 10.0
    plant_model: str | None = None
    """Path of a diagnosis model file (``serpar diagnose --report``'s ``<stem>.model.json``, or
    the MJCF ``serpar export-mjcf`` / ``diagnose --mjcf`` wrote of it): the simulated arm gets
    the physics that diagnosis found (the controllers keep their nominal model) (sim/plants/from_model_file.py; its
    joint friction, if any, replaces arm_friction). None = the nominal arm."""

    contact_friction: float | None = None
    """Journal/bore sliding friction of the cell (None: ``PhysicsConfig.precision_friction``);
    a concealed effect for the diagnosis of insertions (diagnosis/insertion_friction.py)."""

    def __post_init__(self) -> None:
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed!r}")
        if isinstance(self.holes, int):
            if not 1 <= self.holes <= N_HOLES:
                raise ConfigError(f"holes={self.holes}: a count in 1..{N_HOLES} or a list of hole indices")
        elif not self.holes or any(not 0 <= h < N_HOLES for h in self.holes) or len(set(self.holes)) != len(self.holes):
            raise ConfigError(f"holes {self.holes}: distinct indices in 0..{N_HOLES - 1}")
        if self.controller not in CONTROLLERS:
            raise ConfigError(f"controller {self.controller!r}; valid: {', '.join(CONTROLLERS)}")
        if not 0 <= self.arm_friction <= 3:
            raise ConfigError(f"arm_friction {self.arm_friction}: valid 0..3 (fraction of a real Panda's)")
        if self.arm_friction_form not in FRICTION_FORMS:
            raise ConfigError(f"arm_friction_form {self.arm_friction_form!r}; valid: {', '.join(FRICTION_FORMS)}")
        if self.arm_friction_form == "gaz" and not 0 < self.arm_friction <= MAX_SCALE:
            raise ConfigError(f"arm_friction {self.arm_friction} with arm_friction_form gaz: valid "
                              f"0 < arm_friction <= {MAX_SCALE} (times a real Panda's)")
        if self.tolerance_distribution not in DISTRIBUTIONS:
            raise ConfigError(f"tolerance_distribution {self.tolerance_distribution!r}; valid: {', '.join(DISTRIBUTIONS)}")
        if self.camera_width not in CAMERA_WIDTHS:
            raise ConfigError(f"camera_width {self.camera_width}; valid: {', '.join(map(str, CAMERA_WIDTHS))}")
        if not 1 <= self.damage_force_n <= 200 or not 0.5 <= self.hole_time_limit_s <= 120:
            raise ConfigError("damage_force_n in 1..200 N, hole_time_limit_s in 0.5..120 s")
        if not isinstance(self.stewart_calibration, str) or not self.stewart_calibration:
            raise ConfigError(f"stewart_calibration {self.stewart_calibration!r}; valid: "
                              f"{', '.join(CALIBRATIONS)} or the path of a parameters file")
        if self.calibration_file is not None and not self.stewart_correction:
            raise ConfigError("stewart_calibration is a file but stewart_correction is off: it would be unused")
        if self.plant_model is not None:
            arm_plant_of(self.plant_model)  # a missing or bad file fails here, not in an episode
        if self.contact_friction is not None and not 0.01 <= self.contact_friction <= 1.5:
            raise ConfigError(f"contact_friction {self.contact_friction}: valid 0.01..1.5 or null")

    @property
    def calibration_file(self) -> str | None:
        """The parameters file named by stewart_calibration, None for 'campaign' or 'none'."""
        return None if self.stewart_calibration in CALIBRATIONS else self.stewart_calibration


def arm_plant_of(path: str | None) -> ArmPlantChanges | None:
    if path is None:
        return None
    if not isinstance(path, str) or not path:
        raise ConfigError(f"plant_model {path!r}: the path of a diagnosis model file "
                          "(.model.json or the MJCF serpar export-mjcf wrote), or null")
    return arm_plant_changes(read_any_model(path))


def scene_config(cfg: EpisodeConfig) -> SceneConfig:
    """The cell of an episode: its seed's tolerance draw, the hidden Stewart errors, the
    arm's joint friction and the diagnosed arm plant."""
    friction = tuple(cfg.arm_friction * f for f in PANDA_COULOMB_FRICTION) if cfg.arm_friction else ()
    plant = arm_plant_of(cfg.plant_model)
    if (plant is not None and plant.frictionloss) or cfg.arm_friction_form == "gaz":
        # a diagnosis fits the total dry friction against a frictionless arm; the Gaz form is
        # the runtime's drive torque (drive_friction below), not a joint element
        friction = ()
    physics = (PhysicsConfig() if cfg.contact_friction is None
               else PhysicsConfig(precision_friction=cfg.contact_friction))
    return SceneConfig(seed=cfg.seed, tolerance_distribution=cfg.tolerance_distribution,
                       stewart=StewartConfig(joint_errors=cfg.hidden_errors.draw(cfg.seed)),
                       arm_joint_friction=friction, arm_plant=plant, physics=physics)


CELL_LOG_KEYS = ("seed", "holes", "controller", "stewart_correction", "stewart_calibration",
                 "tolerance_distribution", "camera_width", "damage_force_n", "hole_time_limit_s")
"""What a real cell's own log says of an episode: the task and the part population, not the
physics (arm friction, plant model, contact friction, the platform's hidden errors, noise)."""


def cell_log(cfg: EpisodeConfig) -> dict[str, object]:
    """The episode config as a real cell's log would give it (:data:`CELL_LOG_KEYS`)."""
    return {k: getattr(cfg, k) if k != "holes" or isinstance(cfg.holes, int) else list(cfg.holes)
            for k in CELL_LOG_KEYS}


def drive_friction(cfg: EpisodeConfig, scene: Scene) -> DriveFriction | None:
    """The runtime's drive friction of an episode's arm, or None: the config's 'gaz' form
    (unless the plant model's joint friction replaces the config's friction, as in
    :func:`scene_config`) plus the plant model's own drive friction (sigmoid, Stribeck), on
    ``scene`` (built from :func:`scene_config`: its plant and its longest step)."""
    plant = scene.config.arm_plant
    law = DriveFrictionLaw()
    if cfg.arm_friction_form == "gaz" and not (plant is not None and plant.frictionloss):
        law = DriveFrictionLaw.gaz(cfg.arm_friction)
    if plant is not None and plant.drive is not None:
        law = law.plus(plant.drive)
    return (DriveFriction.of_arm(scene.model, names.ARM, law, scene.config.physics.longest_step)
            if law else None)


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % (by default) Wilson score interval of a success rate."""
    if n <= 0 or not 0 <= successes <= n:
        raise ConfigError(f"wilson_interval: need 0 <= successes <= n and n > 0, got {successes}/{n}")
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)
