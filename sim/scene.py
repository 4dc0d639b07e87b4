"""The assembly cell, assembled in code from the per-object specs with MjSpec.attach.

World frame = arm base frame (the Panda's link0). The Stewart base, the tray
pedestal and the cameras are placed around it; the baseplate rides on the
Stewart platform's fixture site.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from serpar.errors import ConfigError, SerparError
from serpar.sim import names
from serpar.sim.arm import ACTUATOR_NAMES, HOME_Q, JOINT_NAMES, PAD_GEOMS, build_arm_spec
from serpar.sim.baseplate import BaseplateConfig, build_baseplate_spec
from serpar.sim.calibration_board import CheckerboardConfig, add_board
from serpar.sim.cameras import DEFAULT_PAIRS, SENSOR_PIXELS, StereoPairConfig, add_stereo_pair
from serpar.sim.conductor import ConductorConfig, build_conductor_spec
from serpar.sim.contact import add_pad_pairs, add_plate_contact_sensor
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_changes import ArmPlantChanges, apply_arm_plant
from serpar.sim.seat_lock import PLATE_BODY
from serpar.sim.stewart import StewartConfig, build_stewart_spec, home_strokes
from serpar.sim.tolerances import DISTRIBUTIONS, DrawnDiameters, draw_diameters
from serpar.sim.tray import TrayConfig, build_tray_spec


@dataclass(frozen=True)
class SceneConfig:
    """Everything that defines one cell instance. Frozen; validated on construction."""

    seed: int = 0
    """Seeds the tolerance draws (hole and journal diameters)."""
    n_conductors: int = 36
    tolerance_distribution: str = "uniform"
    physics: PhysicsConfig = field(default_factory=PhysicsConfig)
    baseplate: BaseplateConfig = field(default_factory=BaseplateConfig)
    tray: TrayConfig = field(default_factory=TrayConfig)
    conductor: ConductorConfig = field(default_factory=ConductorConfig)
    stewart: StewartConfig = field(default_factory=StewartConfig)
    stereo_pairs: tuple[StereoPairConfig, ...] = DEFAULT_PAIRS
    stewart_base: tuple[float, float, float] = (0.60, 0.0, 0.01)
    """Stewart base-joint plane in the world; its 10 mm base disc stands on the floor."""
    tray_position: tuple[float, float, float] = (0.60, 0.27, 0.0)
    tray_height: float = 0.22
    """Height of the tray's bottom face on its pedestal [m]."""
    backlight_position: tuple[float, float, float] = (0.45, -0.17, 0.35)
    arm_joint_friction: tuple[float, ...] = ()
    """Dry friction per arm joint [N m] (MuJoCo frictionloss), a property of the plant that the
    arm controllers do not model; () = frictionless (the nominal model)."""
    calibration_board: CheckerboardConfig | None = None
    """A checkerboard mounted on the hand for camera calibration (None: the working gripper only)."""
    arm_plant: ArmPlantChanges | None = None
    """The arm's physics beyond the nominal MJCF, from a diagnosis of the real cell
    (``EpisodeConfig.plant_model``; sim/plants/arm_changes.py). Its joint friction, when it sets one,
    replaces ``arm_joint_friction``."""

    def __post_init__(self) -> None:
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise ConfigError(f"seed must be a non-negative integer, got {self.seed!r}")
        friction = self.arm_joint_friction
        if friction and (len(friction) != len(JOINT_NAMES) or not all(0 <= f <= 20 for f in friction)):
            raise ConfigError(f"arm_joint_friction {friction}: () or {len(JOINT_NAMES)} values in 0..20 N m")
        if self.arm_plant is not None and not isinstance(self.arm_plant, ArmPlantChanges):
            raise ConfigError("arm_plant comes from a diagnosis model file (EpisodeConfig."
                              f"plant_model), not a {type(self.arm_plant).__name__}")
        if not 0 <= self.n_conductors <= self.tray.n_pockets:
            raise ConfigError(f"n_conductors={self.n_conductors}: valid 0..{self.tray.n_pockets} (tray pockets)")
        if self.tolerance_distribution not in DISTRIBUTIONS:
            raise ConfigError(f"tolerance_distribution {self.tolerance_distribution!r}; "
                              f"valid: {', '.join(DISTRIBUTIONS)}")

    def draw_diameters(self) -> DrawnDiameters:
        return draw_diameters(self.seed, self.baseplate.n_holes, self.n_conductors,
                              self.tolerance_distribution)  # type: ignore[arg-type]


def _add_environment(spec: mujoco.MjSpec, cfg: SceneConfig) -> None:
    world = spec.worldbody
    spec.visual.global_.offwidth, spec.visual.global_.offheight = SENSOR_PIXELS
    spec.visual.quality.shadowsize = 4096
    # Round parts render round: with the default 28 slices a Ø5 mm body's silhouette sits up to
    # 16 um inside its true surface, a visible error to the in-hand cameras (0.028 mm per pixel).
    spec.visual.quality.numslices = 128  # polygon error r(1 - cos(pi/128)) = 0.75 um on the body
    spec.visual.headlight.ambient = [0.25, 0.25, 0.25]
    spec.visual.headlight.diffuse = [0.3, 0.3, 0.3]
    spec.visual.headlight.specular = [0.05, 0.05, 0.05]
    spec.add_texture(name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D,
                     builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, rgb1=[0.42, 0.44, 0.46],
                     rgb2=[0.38, 0.40, 0.42], width=512, height=512)
    floor_mat = spec.add_material(name="floor")
    floor_mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = "grid"
    floor_mat.texrepeat = [8, 8]
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.05], material="floor")
    world.add_light(name="key", pos=[0.3, -0.4, 1.8], dir=[0.15, 0.2, -1], diffuse=[0.45, 0.45, 0.45],
                    castshadow=True)
    world.add_light(name="fill", pos=[1.2, 0.8, 1.5], dir=[-0.5, -0.4, -1], diffuse=[0.2, 0.2, 0.2],
                    castshadow=False)
    tx, ty, _ = cfg.tray_position
    pedestal_h = cfg.tray_height
    world.add_geom(name="tray_pedestal", type=mujoco.mjtGeom.mjGEOM_BOX,
                   size=[0.05, 0.05, pedestal_h / 2], pos=[tx, ty, pedestal_h / 2],
                   rgba=[0.35, 0.36, 0.38, 1])
    bx, by, bz = cfg.backlight_position
    # Diffuse backlight panel behind the in-hand inspection point: the journal is seen in silhouette.
    world.add_geom(name="backlight", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.08, 0.002, 0.05],
                   pos=[bx, by, bz], rgba=[1, 1, 1, 1], contype=0, conaffinity=0,
                   material=_emissive(spec))
    world.add_geom(name="backlight_post", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                   size=[0.008, (bz - 0.05) / 2, 0], pos=[bx, by + 0.01, (bz - 0.05) / 2],
                   rgba=[0.3, 0.3, 0.32, 1])


def _emissive(spec: mujoco.MjSpec) -> str:
    mat = spec.add_material(name="backlight")
    mat.emission = 1.0
    mat.rgba = [1, 1, 1, 1]
    return "backlight"


def attach_cell_arm(spec: mujoco.MjSpec, physics: PhysicsConfig, joint_friction: tuple[float, ...] = (),
                    plant: ArmPlantChanges | None = None,
                    base: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    """The cell's arm with its base at ``base`` (the world origin in the cell; prefix ``arm/``):
    its joints' dry friction, a diagnosed plant over it, the friction rows' stiffness and the
    pads' contact softness."""
    arm = build_arm_spec()
    for joint, friction in zip(JOINT_NAMES, joint_friction):
        arm.joint(joint).frictionloss = friction
    if plant is not None:  # after the nominal friction: a diagnosed one replaces it
        apply_arm_plant(arm, plant, physics.timestep)
    for joint in JOINT_NAMES:  # whichever dry friction the joints have, its rows' stiffness
        arm.joint(joint).solref_friction = [physics.arm_friction_timeconst, 1.0]
    spec.attach(arm, prefix=names.ARM, frame=spec.worldbody.add_frame(pos=list(base)))
    for pad in PAD_GEOMS:
        spec.geom(names.ARM + pad).solref = list(physics.grip_solref)


def build_scene_spec(cfg: SceneConfig = SceneConfig()) -> tuple[mujoco.MjSpec, DrawnDiameters]:
    """The whole cell as one MjSpec, plus the tolerance draw it was built with."""
    diameters = cfg.draw_diameters()
    spec = mujoco.MjSpec()
    spec.modelname = "serpar_cell"
    cfg.physics.apply(spec)
    _add_environment(spec, cfg)
    world = spec.worldbody
    attach_cell_arm(spec, cfg.physics, cfg.arm_joint_friction, cfg.arm_plant)
    if cfg.calibration_board is not None:
        add_board(spec, cfg.calibration_board)
    spec.attach(build_stewart_spec(cfg.stewart, cfg.physics), prefix=names.STEWART,
                frame=world.add_frame(pos=list(cfg.stewart_base)))
    plate = build_baseplate_spec(diameters.holes, cfg.baseplate, cfg.physics)
    fixture_site = spec.site(names.STEWART + "fixture")
    spec.attach(plate, prefix=names.PLATE, site=fixture_site)
    tx, ty, _ = cfg.tray_position
    spec.attach(build_tray_spec(cfg.tray), prefix=names.TRAY,
                frame=world.add_frame(pos=[tx, ty, cfg.tray_height]))
    pockets = cfg.tray.pocket_centres().reshape(-1, 2)
    # Shoulder 1 um above the support balls: no initial overlap.
    top = cfg.tray_height + cfg.tray.thickness + cfg.tray.support_height + 1e-6
    for k in range(cfg.n_conductors):
        part = build_conductor_spec(diameters.journals[k], diameters.bodies[k], cfg.conductor, cfg.physics)
        px, py = pockets[k]
        spec.attach(part, prefix=names.conductor(k), frame=world.add_frame(pos=[tx + px, ty + py, top]))
        # The pads grip a conductor's body through explicit pairs: their friction rows need their
        # own damping, or a held part drifts in the pads on every move (sim/physics.py).
        add_pad_pairs(spec, [names.ARM + pad for pad in PAD_GEOMS], f"{names.conductor(k)}body", cfg.physics)
    if cfg.n_conductors:
        add_plate_contact_sensor(spec, names.conductor_body(0), PLATE_BODY)
    for pair in cfg.stereo_pairs:
        add_stereo_pair(spec, pair)
    return spec, diameters


_SHIFTING = (names.TRAY, "conductor")
"""Name starts of the bodies whose ids a recompile may shift (see :meth:`Scene.recompile`)."""
_COUNTS = {mujoco.mjtObj.mjOBJ_BODY: "nbody", mujoco.mjtObj.mjOBJ_JOINT: "njnt", mujoco.mjtObj.mjOBJ_GEOM: "ngeom",
           mujoco.mjtObj.mjOBJ_SITE: "nsite", mujoco.mjtObj.mjOBJ_ACTUATOR: "nu",
           mujoco.mjtObj.mjOBJ_SENSOR: "nsensor", mujoco.mjtObj.mjOBJ_CAMERA: "ncam"}


def _fixed_ids(model: mujoco.MjModel) -> dict[tuple[mujoco.mjtObj, str], int]:
    """Ids of every named element outside the tray and the conductors."""
    out = {}
    for kind, count in _COUNTS.items():
        for i in range(getattr(model, count)):
            name = mujoco.mj_id2name(model, kind, i) or ""
            if name and not name.startswith(_SHIFTING):
                out[(kind, name)] = i
    return out


def _conductor_bodies(model: mujoco.MjModel, n: int) -> np.ndarray:
    return np.array([model.body(names.conductor_body(k)).id for k in range(n)], dtype=int)


@dataclass
class Scene:
    """A compiled cell: model, data and the ids looked up once after compile."""

    config: SceneConfig
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    data: mujoco.MjData
    diameters: DrawnDiameters
    arm_qpos_adr: np.ndarray
    arm_dof_adr: np.ndarray
    arm_actuators: np.ndarray
    leg_actuators: np.ndarray
    hole_sites: np.ndarray
    conductor_bodies: np.ndarray
    on_recompile: list[Callable[[Scene], None]] = field(default_factory=list)
    """Called after :meth:`recompile` with the scene: holders of the old model or data rebind."""

    def recompile(self) -> None:
        """Compile the edited spec and carry the state over (MjSpec.recompile maps joints,
        controls and activations by name, and keeps the time). `model` and `data` are new
        objects afterwards. Only the tray's and the conductors' ids may move (a conductor body
        moved into the plate); a change that shifts any other id, which controllers and
        recorders hold, raises SerparError."""
        before = _fixed_ids(self.model)
        model, data = self.spec.recompile(self.model, self.data)
        after = _fixed_ids(model)
        if after != before:
            moved = sorted(name for (kind, name), i in before.items() if after.get((kind, name)) != i)
            raise SerparError(f"recompiling moved the ids of {len(moved)} elements outside the tray and "
                           f"conductors (e.g. {moved[:3]}): controllers hold those ids")
        self.model, self.data = model, data
        self.conductor_bodies = _conductor_bodies(model, self.config.n_conductors)
        mujoco.mj_forward(model, data)
        for hook in self.on_recompile:
            hook(self)

    def reset(self) -> None:
        """Home state: arm in its ready pose, Stewart at home, conductors in the tray."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[self.arm_qpos_adr] = HOME_Q
        self.data.ctrl[self.leg_actuators] = home_strokes(self.config.stewart)
        mujoco.mj_forward(self.model, self.data)
        self.gravity_hold_arm()
        self._hold_delayed_commands()
        mujoco.mj_forward(self.model, self.data)  # sensors (joint torques) see the held arm

    def _hold_delayed_commands(self) -> None:
        """A delayed arm actuator (``ArmPlantChanges.actuation_delay``) acts on its command
        history: fill it with the holding torque, else the arm falls for the delay's length
        after every reset."""
        for act in self.arm_actuators:
            n = int(self.model.actuator_history[act, 0])
            if n:
                mujoco.mj_initCtrlHistory(self.model, self.data, int(act), None,
                                          np.full((n, 1), self.data.ctrl[act]))

    def gravity_hold_arm(self) -> None:
        """Arm motor torques = gravity + Coriolis bias (needs an up-to-date qfrc_bias)."""
        self.data.ctrl[self.arm_actuators] = self.data.qfrc_bias[self.arm_dof_adr]

    def camera_names(self) -> list[str]:
        return [self.model.camera(i).name for i in range(self.model.ncam)]


def build_scene(cfg: SceneConfig = SceneConfig()) -> Scene:
    """Build, compile and reset the cell."""
    spec, diameters = build_scene_spec(cfg)
    model = spec.compile()
    data = mujoco.MjData(model)
    arm_joints = [model.joint(names.ARM + j) for j in JOINT_NAMES]
    arm_adr = np.array([j.qposadr[0] for j in arm_joints])
    arm_dof = np.array([j.dofadr[0] for j in arm_joints])
    arm_act = np.array([model.actuator(names.ARM + a).id for a in ACTUATOR_NAMES])
    legs = np.array([model.actuator(f"{names.STEWART}leg{i}").id for i in range(1, 7)])
    holes = np.array([model.site(f"{names.PLATE}hole{k}").id for k in range(cfg.baseplate.n_holes)])
    bodies = _conductor_bodies(model, cfg.n_conductors)
    scene = Scene(cfg, spec, model, data, diameters, arm_adr, arm_dof, arm_act, legs, holes, bodies)
    scene.reset()
    return scene
