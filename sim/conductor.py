"""The conductor: Ø5.0 body, 10 mm long, with a Ø1.700 h6 journal 1.5 mm long (seed 000 Table 1).

Frame: origin at the shoulder (where the journal meets the body), z along the
body, the journal points to -z. The journal is a cylinder primitive (exact
analytic contact with the bore boxes) plus a convex frustum mesh for the tip
chamfer; the frustum's vertices lie on the journal radius, so its facets never
stick out of the cylinder.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim import collision
from serpar.sim.physics import PhysicsConfig
from serpar.sim.tolerances import BODY_H6, JOURNAL_H6

CONDUCTOR_RGBA = (0.80, 0.62, 0.25, 1.0)  # brass
JOURNAL_RGBA = (0.85, 0.70, 0.35, 1.0)


@dataclass(frozen=True)
class ConductorConfig:
    """Conductor dimensions [m] and material."""

    body_length: float = 0.010
    journal_length: float = 0.0015
    tip_chamfer: float = 1e-4
    """45 deg chamfer at the journal tip, leg length."""
    density: float = 8500.0
    """Brass [kg/m^3]."""
    tip_facets: int = 48
    tip_inset: float = 0.0
    """How far inside the journal's radius the tip frustum's top ring lies [m]. At 0 its
    vertices lie on the journal cylinder's bottom edge, so where the edge meets the bore the
    tip can touch at the same place (docs/montecarlo.md, "The float64 jams on warp")."""

    def __post_init__(self) -> None:
        if not 0 <= self.tip_inset < self.tip_chamfer:
            raise ConfigError(f"tip_inset {self.tip_inset} m must be in [0, tip_chamfer={self.tip_chamfer})")
        if not 0 < self.tip_chamfer < self.journal_length / 2:
            raise ConfigError(f"tip_chamfer {self.tip_chamfer} m must be in (0, journal_length/2)")
        if self.body_length <= 0 or self.journal_length <= 0:
            raise ConfigError("body_length and journal_length must be > 0")


def mass_properties(config: ConductorConfig, journal_diameter: float, body_diameter: float
                    ) -> tuple[float, float]:
    """(mass [kg], CoM height above the shoulder along the conductor's z [m]) of a conductor
    of these diameters: the body and journal cylinders (the tip chamfer's few micrograms left
    out). What a cell's task knows of the part it carries, from the drawing."""
    lb, lj = config.body_length, config.journal_length
    m_body = config.density * np.pi * body_diameter**2 / 4 * lb
    m_journal = config.density * np.pi * journal_diameter**2 / 4 * lj
    mass = m_body + m_journal
    return float(mass), float((m_body * lb / 2 - m_journal * lj / 2) / mass)


def _frustum_vertices(r_top: float, r_bottom: float, z_top: float, z_bottom: float, n: int):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    top = np.c_[r_top * np.cos(a), r_top * np.sin(a), np.full(n, z_top)]
    bot = np.c_[r_bottom * np.cos(a), r_bottom * np.sin(a), np.full(n, z_bottom)]
    return np.r_[top, bot]


def add_conductor_geoms(
    spec: mujoco.MjSpec,
    body: mujoco.MjsBody,
    journal_diameter: float,
    body_diameter: float,
    config: ConductorConfig = ConductorConfig(),
    physics: PhysicsConfig = PhysicsConfig(),
    mesh_name: str = "journal_tip",
) -> None:
    """Add the conductor's geoms and sites to `body` (frame as in the module docstring)."""
    for name, d, band in (("journal", journal_diameter, JOURNAL_H6), ("body", body_diameter, BODY_H6)):
        if not band.min - 1e-12 <= d <= band.max + 1e-12:
            raise ConfigError(f"{name} diameter {d} m outside its h6 band {band.min}..{band.max}")
    r, c, lj, lb = journal_diameter / 2, config.tip_chamfer, config.journal_length, config.body_length
    spec.add_mesh(
        name=mesh_name,
        uservert=_frustum_vertices(r - config.tip_inset, r - c - config.tip_inset, -lj + c, -lj,
                                   config.tip_facets).ravel().tolist(),
    )
    geoms = [
        body.add_geom(name="body", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                      size=[body_diameter / 2, lb / 2, 0], pos=[0, 0, lb / 2], rgba=list(CONDUCTOR_RGBA)),
        body.add_geom(name="journal", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                      size=[r, (lj - c) / 2, 0], pos=[0, 0, -(lj - c) / 2], rgba=list(JOURNAL_RGBA)),
        body.add_geom(name="tip", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh_name,
                      rgba=list(JOURNAL_RGBA)),
    ]
    for geom in geoms:
        geom.density = config.density
        physics.precision_contact(geom)
    collision.conductor_body(geoms[0])
    body.add_site(name="tip", pos=[0, 0, -lj], size=[1e-4, 0, 0], group=5)
    body.add_site(name="shoulder", pos=[0, 0, 0], size=[1e-4, 0, 0], group=5)
    body.add_site(name="top", pos=[0, 0, lb], size=[1e-4, 0, 0], group=5)


def build_conductor_spec(
    journal_diameter: float,
    body_diameter: float,
    config: ConductorConfig = ConductorConfig(),
    physics: PhysicsConfig = PhysicsConfig(),
) -> mujoco.MjSpec:
    """MjSpec with one free body 'conductor' (free joint 'free')."""
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="conductor")
    body.add_freejoint(name="free")
    add_conductor_geoms(spec, body, journal_diameter, body_diameter, config, physics)
    return spec
