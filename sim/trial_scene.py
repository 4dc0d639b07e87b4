"""The insertion trial's scene: what one insertion can touch, and nothing else.

The cell's arm (its dry joint friction, gripper and pads as in the episode), one conductor and
a patch of baseplate with one faceted bore whose entry is at the insertion station, where the
Stewart platform brings every hole. The platform's legs are left out: once the journal tip is
within ``FOLLOW_STOP_ABOVE`` of the entry the episode's platform holds still (it stops
following the TCP there, tasks/episode_steps.py) and its legs are ~100x stiffer than the arm
at the tool, so the plate stands still in the world then and what the platform contributes is
where the hole ends up (a sampled position error). Before that moment the platform follows the
TCP's sideways wander; the plate is a mocap body, so a trial moves it as the platform does
(kinematically: nothing touches it then). No tray, cameras, lights or other holes: a trial
steps ~2x faster than the cell at rest (``serpar bench``).

Per trial, the bore and the journal take their drawn diameters: one model per trial compiled
from the same spec (the same sizes, so one ``mujoco.batch.Batch`` runs them all).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import (
    ACTUATOR_NAMES,
    BASE_BODY,
    FINGER_JOINT_NAMES,
    JOINT_NAMES,
    PAD_GEOMS,
    TCP_SITE,
)
from serpar.sim.baseplate import BaseplateConfig, build_baseplate_spec
from serpar.sim.conductor import ConductorConfig, build_conductor_spec
from serpar.sim.contact import PLATE_CONTACT, add_pad_pairs, add_plate_contact_sensor
from serpar.sim.physics import PhysicsConfig
from serpar.sim.scene import attach_cell_arm
from serpar.sim.seat_lock import PLATE_BODY
from serpar.sim.tolerances import BODY_H6, HOLE_H7, JOURNAL_H6

STATION_ENTRY: tuple[float, float, float] = (0.60, 0.0, 0.299)
"""Where the platform brings each hole's entry in the cell [m] (tasks/episode_steps.py)."""
PATCH = BaseplateConfig(rows=1, cols=1, margin=0.025)
"""One hole in 60 mm square of plate (the plate's thickness and bore): a journal positioned
mm off (seed 001's error budget) still lands on plate, as it would in the cell."""
PART = 0
"""The trial's one conductor carries the cell's first conductor's names (``conductor0/``)."""


@dataclass(frozen=True)
class TrialSceneConfig:
    """What a trial scene is built from; the per-trial diameters come with each build."""

    physics: PhysicsConfig = field(default_factory=lambda: PhysicsConfig(sleep=False))
    """The cell's physics without island sleeping: nothing in a trial rests long (the plate is
    static, the arm never sleeps), and a non-persistent batch cannot carry sleep's state."""
    conductor: ConductorConfig = field(default_factory=ConductorConfig)
    chamfer: float = PATCH.chamfer
    """The bore's entry chamfer leg [m]."""
    arm_joint_friction: tuple[float, ...] = ()
    """Dry friction per arm joint [N m], as ``SceneConfig.arm_joint_friction``."""
    entry: tuple[float, float, float] = STATION_ENTRY
    """The hole's entry in the arm's base frame [m]."""
    at_origin: bool = False
    """Put the world origin at the hole's entry (the arm's base at -entry): a float32 engine
    (MuJoCo Warp) resolves ~2 nm there against ~60 nm at the entry's 0.6 m from the base. The
    physics is the same; only where the world's origin sits moves."""
    seat_plane: bool = False
    """The seat (the plate's top face, where the part's shoulder lands) as a plane at that face
    instead of the cell's box. Only the part's body touches it, so the box's extent never
    matters; but MuJoCo Warp's float32 box-cylinder collision, with the shoulder resting on the
    face, now and then returns the box's side as the separating axis (a 32 mm deep contact
    along -y: a seated trial blew up); plane-cylinder is analytic (docs/montecarlo.md)."""
    rounding: tuple[float, float] = (0.0, 0.0)
    """Round the edges of the part's journal and body cylinders by these radii [m]: each
    cylinder shrunk by its radius (radius and both ends) with that contact margin (also on
    its explicit pairs), which MuJoCo's collision adds back around the shrunk shape, so
    every contact is active from the original surface on and only the edges round off. The
    collision of such a pair starts as a distance query between separated shapes, which
    float32 resolves where a shallow overlap of a cylinder's side along a face does not.
    (0, 0): the sharp cylinders."""

    @property
    def base(self) -> tuple[float, float, float]:
        """The arm's base in the world [m]."""
        return tuple(-v for v in self.entry) if self.at_origin else (0.0, 0.0, 0.0)  # type: ignore[return-value]

    def __post_init__(self) -> None:
        if len(self.entry) != 3 or not all(np.isfinite(self.entry)):
            raise ConfigError(f"entry {self.entry}: three finite coordinates [m]")
        BaseplateConfig(rows=1, cols=1, margin=PATCH.margin, chamfer=self.chamfer)  # validates it
        if len(self.rounding) != 2 or not all(0 <= r < 1e-3 for r in self.rounding):
            raise ConfigError(f"rounding {self.rounding}: two edge radii [m] (journal, body) in [0, 1e-3)")
        if self.arm_joint_friction and len(self.arm_joint_friction) != len(JOINT_NAMES):
            raise ConfigError(f"arm_joint_friction: () or {len(JOINT_NAMES)} values [N m]")

    @property
    def plate(self) -> BaseplateConfig:
        return BaseplateConfig(rows=1, cols=1, margin=PATCH.margin, chamfer=self.chamfer)


def _seat_as_plane(spec: mujoco.MjSpec, top: float, part_geom: str) -> None:
    """The seat box as a plane at its top face, touching the part's body only, through an
    explicit pair with the contact the box's collision bits gave (both geoms carry the same
    precision-contact settings at equal priority, so MuJoCo's mix is the seat's own): an
    infinite plane on the bits would also meet the arm's links below the plate."""
    seat = spec.geom(names.PLATE + "seat")
    seat.type, seat.pos = mujoco.mjtGeom.mjGEOM_PLANE, [0.0, 0.0, top]
    seat.size = [seat.size[0], seat.size[1], 1e-3]  # a plane's size: drawn extent, grid
    seat.contype = seat.conaffinity = 0
    mu, spin, roll = seat.friction
    spec.add_pair(name=f"{names.PLATE}seat|{part_geom}", geomname1=names.PLATE + "seat",
                  geomname2=part_geom, condim=seat.condim, friction=[mu, mu, spin, roll, roll],
                  solref=list(seat.solref), solimp=list(seat.solimp), margin=seat.margin,
                  gap=seat.gap)


def _fix_inertial(part: mujoco.MjSpec) -> None:
    """Write the part's body inertial as compiled from its geoms, so that shrinking them
    (``_round_cylinder``) moves no mass."""
    model = part.compile()
    body, compiled = part.body("conductor"), model.body("conductor")
    body.explicitinertial = True
    body.mass, body.ipos = float(compiled.mass[0]), compiled.ipos.copy()
    body.iquat, body.inertia = compiled.iquat.copy(), compiled.inertia.copy()


def _round_cylinder(spec: mujoco.MjSpec, name: str, radius: float) -> None:
    """Cylinder geom ``name`` shrunk by ``radius`` more, its margin grown by as much
    (TrialSceneConfig.rounding; the journal's edge round, ConductorConfig.edge_radius, adds to
    it: the contact surface stays the sharp cylinder's sides and ends)."""
    geom = spec.geom(name)
    r, half = geom.size[0], geom.size[1]
    if not 0 < radius < min(r, half):
        raise ConfigError(f"rounding {radius} m of {name}: must be in (0, {min(r, half)})")
    geom.size = [r - radius, half - radius, 0.0]
    geom.margin += radius
    for pair in spec.pairs:
        if name in (pair.geomname1, pair.geomname2):
            pair.margin += radius


def _check(name: str, value: float, band: object) -> None:
    lo, hi = band.min, band.max  # type: ignore[attr-defined]
    if not lo - 1e-12 <= value <= hi + 1e-12:
        raise ConfigError(f"{name} diameter {value * 1e3:.4f} mm outside {lo * 1e3:.4f}..{hi * 1e3:.4f} mm")


def build_trial_spec(cfg: TrialSceneConfig, hole: float, journal: float,
                     body: float = BODY_H6.nominal) -> mujoco.MjSpec:
    """The trial scene with these diameters [m] (H7 hole, h6 journal and body)."""
    _check("hole", hole, HOLE_H7)
    _check("journal", journal, JOURNAL_H6)
    _check("body", body, BODY_H6)
    spec = mujoco.MjSpec()
    spec.modelname = "serpar_trial"
    cfg.physics.apply(spec)
    attach_cell_arm(spec, cfg.physics, cfg.arm_joint_friction, base=cfg.base)
    plate = cfg.plate
    ex, ey, ez = np.asarray(cfg.entry) + np.asarray(cfg.base)  # the entry in the world
    spec.attach(build_baseplate_spec([hole], plate, cfg.physics), prefix=names.PLATE,
                frame=spec.worldbody.add_frame(pos=[ex, ey, ez - plate.thickness]))
    spec.body(PLATE_BODY).mocap = True  # the platform's part: moved, never pushed
    if cfg.seat_plane:
        _seat_as_plane(spec, plate.thickness, f"{names.conductor(PART)}body")
    part = build_conductor_spec(journal, body, cfg.conductor, cfg.physics)
    if any(cfg.rounding):
        _fix_inertial(part)  # the sharp part's mass, centre and inertia, whatever the rounding
    spec.attach(part, prefix=names.conductor(PART),
                frame=spec.worldbody.add_frame(pos=[ex, ey, ez + 0.01]))
    add_pad_pairs(spec, [names.ARM + pad for pad in PAD_GEOMS], f"{names.conductor(PART)}body",
                  cfg.physics)
    for geom, radius in zip(("journal", "body"), cfg.rounding):  # after the pairs: it sets theirs
        if radius:
            _round_cylinder(spec, f"{names.conductor(PART)}{geom}", radius)
    add_plate_contact_sensor(spec, names.conductor_body(PART), PLATE_BODY)
    return spec


@dataclass(frozen=True)
class TrialIds:
    """Addresses in a compiled trial model (equal in every trial's model)."""

    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    arm_actuators: np.ndarray
    finger_qpos: np.ndarray
    part_qpos: int
    """Start of the conductor's free joint in qpos (position, then quaternion)."""
    part_body: int
    tcp_site: int
    hole_site: int
    tip_site: int
    shoulder_site: int
    plate_force: slice
    """sensordata of the conductor/plate contact force."""
    plate_mocap: int
    """The plate's index in mocap_pos."""
    base: np.ndarray
    """The arm's base in the world [m]: a trial's start (the arm's base frame, where its
    controller works) plus this is where its part goes in the world."""

    @classmethod
    def of(cls, model: mujoco.MjModel) -> TrialIds:
        arm = [model.joint(names.ARM + j) for j in JOINT_NAMES]
        fingers = [model.joint(names.ARM + j) for j in FINGER_JOINT_NAMES]
        part = model.body(names.conductor_body(PART))
        prefix = names.conductor(PART)
        sensor = model.sensor(PLATE_CONTACT)
        adr = int(sensor.adr[0])
        return cls(np.array([j.qposadr[0] for j in arm]), np.array([j.dofadr[0] for j in arm]),
                   np.array([model.actuator(names.ARM + a).id for a in ACTUATOR_NAMES]),
                   np.array([j.qposadr[0] for j in fingers]),
                   int(model.jnt_qposadr[part.jntadr[0]]), int(part.id),
                   model.site(names.ARM + TCP_SITE).id, model.site(f"{names.PLATE}hole0").id,
                   model.site(f"{prefix}tip").id, model.site(f"{prefix}shoulder").id,
                   slice(adr, adr + 3), int(model.body_mocapid[model.body(PLATE_BODY).id]),
                   model.body(names.ARM + BASE_BODY).pos.copy())

