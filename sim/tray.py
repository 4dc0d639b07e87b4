"""Parts tray: conductors stand upright, journal down in a 2.6 mm square pocket,
shoulder resting on three support balls around a square pocket (seed 000 §5.2 step 1 finds them by vision).

Frame: origin at the centre of the tray's bottom face, top face at z = thickness.
Pocket k has site ``pocket{k}`` at its entry centre; parts rest on three support
balls whose tops are ``support_height`` above the tray face.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim.holes import add_grid_plate, grid_centres

TRAY_RGBA = (0.15, 0.30, 0.55, 1.0)  # blue ESD-safe polymer: brass parts stand out


@dataclass(frozen=True)
class TrayConfig:
    rows: int = 6
    cols: int = 6
    pitch: float = 0.012
    thickness: float = 0.004
    pocket_diameter: float = 2.6e-3
    """Width of the square pocket the journal hangs in: the tray locates parts to ~0.45 mm."""
    margin: float = 0.006
    support_ball_radius: float = 5e-4
    support_height: float = 3e-4
    """Each pocket seats the shoulder on three balls standing this far above the tray face:
    a kinematic 3-point support (3 contacts per part instead of dozens on a flat face)."""
    support_circle: float = 1.9e-3

    def __post_init__(self) -> None:
        if not (1 <= self.rows <= 20 and 1 <= self.cols <= 20):
            raise ConfigError(f"tray grid {self.rows}x{self.cols}: rows and cols must be in 1..20")
        if not 1.8e-3 <= self.pocket_diameter <= 4.8e-3:
            raise ConfigError("pocket_diameter must be in 1.8..4.8 mm (journal in, body out)")

    @property
    def n_pockets(self) -> int:
        return self.rows * self.cols

    def pocket_centres(self) -> np.ndarray:
        """(rows, cols, 2) pocket centres in the tray frame."""
        return grid_centres(self.rows, self.cols, self.pitch)


def build_tray_spec(config: TrayConfig = TrayConfig()) -> mujoco.MjSpec:
    """MjSpec whose root body 'tray' (no joint) carries the tray plate and pockets."""
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name="tray")
    window = config.pocket_diameter / 2  # square pockets: the plate's bars are the walls

    def setup(geom: mujoco.MjsGeom) -> None:
        geom.rgba = list(TRAY_RGBA)
        geom.density = 1400.0

    centres = config.pocket_centres()
    add_grid_plate(body, centres, config.pitch, config.thickness, config.margin, window, setup)
    for k, (cx, cy) in enumerate(centres.reshape(-1, 2)):
        for j in range(3):
            a = 2 * np.pi * j / 3 + np.pi / 2
            ball = body.add_geom(
                type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[config.support_ball_radius, 0, 0],
                pos=[float(cx + config.support_circle * np.cos(a)),
                     float(cy + config.support_circle * np.sin(a)),
                     config.thickness + config.support_height - config.support_ball_radius],
                rgba=[0.75, 0.75, 0.78, 1])
            ball.density = 7800.0
        body.add_site(name=f"pocket{k}", pos=[float(cx), float(cy), config.thickness],
                      size=[2e-4, 0, 0], rgba=[0, 1, 0, 0], group=5)
    return spec
