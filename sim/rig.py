"""Insertion test rig: one faceted bore and a conductor on a stiff x/y/z carriage.

The carriage stands in for a laterally stiff arm: x/y are position servos,
z is a pure force actuator (positive ctrl presses the journal down). The
carriage is gravity-compensated so the z actuator force is the axial force.
Used by ``serpar validate`` checks 1-3 and by the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim.baseplate import BaseplateConfig, build_baseplate_spec
from serpar.sim.conductor import ConductorConfig, add_conductor_geoms
from serpar.sim.contact import contact_force_on
from serpar.sim.physics import PhysicsConfig


@dataclass(frozen=True)
class RigConfig:
    """Test rig parameters."""

    hole_diameter: float = 1.708e-3
    journal_diameter: float = 1.696e-3
    body_diameter: float = 4.996e-3
    carriage_mass: float = 0.5
    """Effective mass at the tool [kg]; lighter than a Panda's (~1-3 kg), i.e. conservative."""
    lateral_stiffness: float = 1e5
    """Servo stiffness in x and y [N/m], of the order of a stiff arm at the tool."""
    axial_damping: float = 20.0
    """Viscous damping on the z slide [N s/m]: a quasi-static press."""
    plate: BaseplateConfig = BaseplateConfig(rows=1, cols=1, margin=0.004)
    conductor: ConductorConfig = ConductorConfig()

    def __post_init__(self) -> None:
        if self.hole_diameter < self.journal_diameter:
            raise ConfigError("hole_diameter < journal_diameter: H7/h6 is a clearance fit")
        if self.carriage_mass <= 0 or self.lateral_stiffness <= 0:
            raise ConfigError("carriage_mass and lateral_stiffness must be > 0")

    @property
    def radial_clearance(self) -> float:
        return (self.hole_diameter - self.journal_diameter) / 2

    @property
    def capture_radius(self) -> float:
        """Largest lateral offset from which the chamfers still guide the journal in."""
        return self.radial_clearance + self.plate.chamfer + self.conductor.tip_chamfer


@dataclass
class Rig:
    """Compiled rig with the ids the checks need (looked up once)."""

    config: RigConfig
    model: mujoco.MjModel
    data: mujoco.MjData
    hole_top_z: float
    tip_site: int
    conductor_geoms: frozenset[int]

    def place(self, offset_x: float, height: float) -> None:
        """Reset with the journal tip `height` above the hole entry, laterally offset by offset_x."""
        mujoco.mj_resetData(self.model, self.data)
        self.data.qpos[:3] = (offset_x, 0.0, height)
        self.data.ctrl[:3] = (offset_x, 0.0, 0.0)
        mujoco.mj_forward(self.model, self.data)

    def depth(self) -> float:
        """Depth of the journal tip below the hole entry [m] (negative above it)."""
        return self.hole_top_z - float(self.data.site_xpos[self.tip_site][2])

    def max_penetration(self) -> float:
        """Deepest penetration [m] among the conductor's contacts (0 when none), measured from the
        contact surface: a geom with a margin (the journal's edge round) is shrunk by it, so its
        contact's ``dist`` counts from the shrunk shape and the surface is ``includemargin`` out."""
        con = self.data.contact
        n = self.data.ncon
        worst = 0.0
        for i in range(n):
            if con.geom1[i] in self.conductor_geoms or con.geom2[i] in self.conductor_geoms:
                worst = max(worst, float(con.includemargin[i] - con.dist[i]))
        return worst

    def contact_force(self) -> np.ndarray:
        """Total contact force on the conductor in world coordinates [N]."""
        return contact_force_on(self.model, self.data, self.conductor_geoms)


def build_rig(config: RigConfig = RigConfig(), physics: PhysicsConfig = PhysicsConfig()) -> Rig:
    """Compile the rig: plate on the ground, hole 0 at the origin."""
    spec = mujoco.MjSpec()
    physics.apply(spec)
    plate = build_baseplate_spec([config.hole_diameter], config.plate, physics)
    spec.attach(plate, prefix="plate/", frame=spec.worldbody.add_frame(pos=[0, 0, config.plate.fixture_height]))
    top_z = config.plate.fixture_height + config.plate.thickness
    carriage = spec.worldbody.add_body(name="carriage", pos=[0, 0, top_z + config.conductor.journal_length])
    carriage.gravcomp = 1.0
    for axis, name in (([1, 0, 0], "x"), ([0, 1, 0], "y"), ([0, 0, 1], "z")):
        carriage.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis,
                           damping=config.axial_damping if name == "z" else 0.0)
    carriage.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.004, 0.004, 0.002],
                      pos=[0, 0, config.conductor.body_length + 0.002],
                      mass=config.carriage_mass, contype=0, conaffinity=0, rgba=[0.3, 0.3, 0.35, 1])
    add_conductor_geoms(spec, carriage, config.journal_diameter, config.body_diameter,
                        config.conductor, physics)
    kp = config.lateral_stiffness
    kv = 2.0 * np.sqrt(kp * config.carriage_mass)  # critically damped lateral servo
    for name in ("x", "y"):
        act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=kp, kv=kv)
    press = spec.add_actuator(name="press", target="z", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    press.gear[0] = -1.0  # positive ctrl pushes down
    model = spec.compile()
    data = mujoco.MjData(model)
    geoms = frozenset(
        g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("carriage").id
        and model.geom_contype[g] != 0
    )
    return Rig(config, model, data, top_z, model.site("tip").id, geoms)
