"""The conductor: Ø5.0 body, 10 mm long, with a Ø1.700 h6 journal 1.5 mm long (seed 000 Table 1).

Frame: origin at the shoulder (where the journal meets the body), z along the
body, the journal points to -z. The journal is a cylinder primitive (exact
analytic contact with the bore boxes) plus a convex frustum mesh for the tip
chamfer. The edge between them is a fillet (`edge_radius`): the cylinder is
shrunk by the radius and given it as contact margin, so MuJoCo's contact surface
is the sharp cylinder with its edges rounded, and the frustum's 45 deg face is
tangent to that round. A sharp edge there was an artifact either way: with the
frustum's ring on the cylinder's edge both geoms touch the bore at the same
place (a tight fit's jam hinged on it), and with the ring set inside, the
cylinder's flat bottom shows as a ledge that sits on the plate's chamfer corner
(docs/montecarlo.md, "The journal's edge").
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
    edge_radius: float = 10e-6
    """Fillet between the journal's side and its tip chamfer [m] (0: a sharp edge, the ring
    flush on the cylinder's edge). Above the 48-gon's 1.8 um sagitta so that the chamfer's
    flat facets never leave the round's flat bottom exposed."""

    def __post_init__(self) -> None:
        if not 0 <= self.edge_radius <= self.tip_chamfer / 4:
            raise ConfigError(f"edge_radius {self.edge_radius} m must be in [0, tip_chamfer/4="
                              f"{self.tip_chamfer / 4}]")
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


def tip_frustum(r: float, config: ConductorConfig) -> tuple[float, float, float, float]:
    """(top radius, bottom radius, top z, bottom z) [m] of the tip chamfer's frustum on a journal
    of radius ``r``: its 45 deg face on the line tangent to the edge's round (centre
    (r - rho, z_edge + rho) in the section) set 1 % of rho outside it, so the round never
    touches a 45 deg face together with the chamfer, and its top ring at the tangent height,
    where it meets the round with a step of 0.014 rho."""
    rho, c, lj = config.edge_radius, config.tip_chamfer, config.journal_length
    z_edge = -lj + c
    out = np.sqrt(2) * 0.01 * rho  # the face's offset from the tangent line, horizontally
    return (r - (1 - np.sqrt(0.5)) * rho + out, r - c - (2 - np.sqrt(2)) * rho + out,
            z_edge + (1 - np.sqrt(0.5)) * rho, -lj)


def _polygon_frustum_volume(r_top: float, r_bottom: float, height: float, n: int) -> float:
    area = [n / 2 * rr**2 * np.sin(2 * np.pi / n) for rr in (r_top, r_bottom)]
    return float(height / 3 * (area[0] + area[1] + np.sqrt(area[0] * area[1])))


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
    rho = config.edge_radius
    spec.add_mesh(name=mesh_name,
                  uservert=_frustum_vertices(*tip_frustum(r, config), config.tip_facets).ravel().tolist())
    geoms = [
        body.add_geom(name="body", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                      size=[body_diameter / 2, lb / 2, 0], pos=[0, 0, lb / 2], rgba=list(CONDUCTOR_RGBA)),
        body.add_geom(name="journal", type=mujoco.mjtGeom.mjGEOM_CYLINDER,  # shrunk: the round
                      size=[r - rho, (lj - c) / 2 - rho, 0], pos=[0, 0, -(lj - c) / 2],
                      margin=rho, rgba=list(JOURNAL_RGBA)),
        body.add_geom(name="tip", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh_name,
                      rgba=list(JOURNAL_RGBA)),
    ]
    for geom in geoms:
        geom.density = config.density
        physics.precision_contact(geom)
    # the sharp part's masses: the round and the tangent chamfer change the volumes by ~1 %
    geoms[1].mass = config.density * np.pi * r**2 * (lj - c)
    geoms[2].mass = config.density * _polygon_frustum_volume(r, r - c, c, config.tip_facets)
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
