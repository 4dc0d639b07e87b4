"""The baseplate: a rows x cols grid of Ø1.700 H7 bores on a dark fixture block.

Frame: origin at the centre of the plate's bottom face, z up; the plate's top
face (hole entries) is at z = thickness. Holes are numbered row-major from the
-y, -x corner; site ``hole{k}`` sits at each entry centre with z out of the hole.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim import collision
from serpar.sim.holes import BoreGeometry, add_bore, add_grid_plate, grid_centres
from serpar.sim.physics import PhysicsConfig
from serpar.sim.tolerances import HOLE_H7

PLATE_RGBA = (0.62, 0.63, 0.64, 1.0)  # bead-blasted aluminium; below saturation under the cell lights (~200/255)
FIXTURE_RGBA = (0.06, 0.06, 0.07, 1.0)  # black anodised: empty holes look dark from above


@dataclass(frozen=True)
class BaseplateConfig:
    """Geometry of the baseplate and its fixture [m]."""

    rows: int = 6
    cols: int = 6
    pitch: float = 0.010
    thickness: float = 0.004
    """Plate thickness = through-bore depth (the issue asks >= 3 mm; the journal is 1.5 mm)."""
    chamfer: float = 1e-4
    """Entry chamfer leg length at 45 deg (0 allowed)."""
    n_facets: int = 16
    """Boxes per bore: 16 keeps the bore round to 0.16 um at the largest clearance."""
    margin: float = 0.006
    window: float = 0.0025
    """Half-size of the square opening per hole that the bore's ring boxes fill."""
    fixture_height: float = 0.015

    def __post_init__(self) -> None:
        if not (1 <= self.rows <= 20 and 1 <= self.cols <= 20):
            raise ConfigError(f"grid {self.rows}x{self.cols}: rows and cols must be in 1..20")
        if self.thickness < 3e-3:
            raise ConfigError(f"thickness {self.thickness} m: holes must be at least 3 mm deep")
        if not 0 <= self.chamfer <= 5e-4:
            raise ConfigError(f"chamfer {self.chamfer:g} m ({self.chamfer * 1e3:g} mm) outside 0..0.0005 m "
                              "(0..0.5 mm); lengths in a config are in metres")
        if not 2 * self.window + 1e-3 < self.pitch:
            raise ConfigError("window too large for the pitch: holes would merge")

    @property
    def n_holes(self) -> int:
        return self.rows * self.cols

    def hole_centres(self) -> np.ndarray:
        """(rows, cols, 2) hole centres in the plate frame."""
        return grid_centres(self.rows, self.cols, self.pitch)

    def bore(self, diameter: float) -> BoreGeometry:
        outer = self.window * np.sqrt(2) + 2e-4
        return BoreGeometry(diameter, self.thickness, self.chamfer, self.n_facets, float(outer))


def build_baseplate_spec(
    hole_diameters: Sequence[float],
    config: BaseplateConfig = BaseplateConfig(),
    physics: PhysicsConfig = PhysicsConfig(),
) -> mujoco.MjSpec:
    """MjSpec whose root body 'baseplate' (no joint) carries the fixture, plate and bores."""
    if len(hole_diameters) != config.n_holes:
        raise ConfigError(f"{len(hole_diameters)} hole diameters given for {config.n_holes} holes")
    for d in hole_diameters:
        if not HOLE_H7.min - 1e-12 <= d <= HOLE_H7.max + 1e-12:
            raise ConfigError(f"hole diameter {d} m outside H7 band {HOLE_H7.min}..{HOLE_H7.max}")
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="baseplate")
    h = config.fixture_height
    rows, cols = config.rows, config.cols
    half_x = cols * config.pitch / 2 + config.margin
    half_y = rows * config.pitch / 2 + config.margin
    fixture = body.add_geom(
        name="fixture", type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[half_x + 0.004, half_y + 0.004, h / 2], pos=[0, 0, -h / 2], rgba=list(FIXTURE_RGBA),
    )
    fixture.mass = 0.8
    collision.plate_surface(fixture)  # a part's body meets the seat box only

    def plate_geom(geom: mujoco.MjsGeom) -> None:
        geom.rgba = list(PLATE_RGBA)
        geom.density = 2700.0  # aluminium
        physics.precision_contact(geom)
        collision.plate_surface(geom)

    centres = config.hole_centres()
    add_grid_plate(body, centres, config.pitch, config.thickness, config.margin, config.window,
                   plate_geom)
    for k, (cx, cy) in enumerate(centres.reshape(-1, 2)):
        add_bore(spec, body, (float(cx), float(cy)), config.thickness, config.bore(hole_diameters[k]),
                 plate_geom, name=f"bore{k}")
        body.add_site(name=f"hole{k}", pos=[float(cx), float(cy), config.thickness],
                      size=[2e-4, 0, 0], rgba=[1, 0, 0, 0], group=5)
    seat = body.add_geom(name="seat", type=mujoco.mjtGeom.mjGEOM_BOX,
                         size=[half_x, half_y, config.thickness / 2], pos=[0, 0, config.thickness / 2])
    seat.density = 0.0  # the bars and bores carry the plate's mass
    physics.precision_contact(seat)
    collision.plate_seat(seat)
    body.add_site(name="top_centre", pos=[0, 0, config.thickness], size=[1e-3, 0, 0], group=5)
    return spec
