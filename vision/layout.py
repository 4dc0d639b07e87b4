"""Cell-layout priors for the vision: where the tray and the baseplate nominally are, as
base-frame search regions. Layout knowledge (the cell drawing), never a measurement."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.sim.baseplate import BaseplateConfig
from serpar.sim.scene import SceneConfig
from serpar.vision.camera import CameraModel

Vec = NDArray[np.float64]
NOMINAL_CELL = SceneConfig()


@dataclass(frozen=True)
class BoxRegion:
    """Axis-aligned box in the base frame: where a detection may lie [m]."""

    low: tuple[float, float, float]
    high: tuple[float, float, float]

    def contains(self, points: Vec) -> NDArray[np.bool_]:
        p = np.atleast_2d(points)
        return np.all((p >= np.asarray(self.low)) & (p <= np.asarray(self.high)), axis=1)

    def corners(self) -> Vec:
        lo, hi = np.asarray(self.low), np.asarray(self.high)
        return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                         for i in (0, 1) for j in (0, 1) for k in (0, 1)])

    def pixel_window(self, camera: CameraModel, pad: int = 20) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1) of the box's projection in `camera`, padded, clipped to the image."""
        uv = camera.project(self.corners())
        w, h = camera.size
        x0, y0 = np.floor(uv.min(axis=0)).astype(int) - pad
        x1, y1 = np.ceil(uv.max(axis=0)).astype(int) + pad
        return max(0, x0), max(0, y0), min(w, x1), min(h, y1)


def tray_region(cfg: SceneConfig = NOMINAL_CELL, margin: float = 0.004) -> BoxRegion:
    """Where conductor tops can be in the tray: its nominal footprint (cell layout, not a
    measurement), from the tray face to above the tallest upright part."""
    tray = cfg.tray
    tx, ty, _ = cfg.tray_position
    hx = tray.cols * tray.pitch / 2 + tray.margin + margin
    hy = tray.rows * tray.pitch / 2 + tray.margin + margin
    face = cfg.tray_height + tray.thickness
    top = face + tray.support_height + cfg.conductor.body_length
    return BoxRegion((tx - hx, ty - hy, face), (tx + hx, ty + hy, top + 0.006))


def tray_pockets(cfg: SceneConfig = NOMINAL_CELL) -> Vec:
    """Nominal pocket centres (n, 2) in the base frame's xy, row-major (cell layout)."""
    tx, ty, _ = cfg.tray_position
    return cfg.tray.pocket_centres().reshape(-1, 2) + (tx, ty)


@dataclass(frozen=True)
class PlateLayout:
    """Where the plate is nominally (cell layout, not a measurement): the plate frame of
    :mod:`serpar.sim.baseplate` (bottom-face centre, z up) at the Stewart home pose, and how far the
    platform may carry it from there."""

    origin: tuple[float, float, float]
    rotation: tuple[tuple[float, ...], ...] = ((1.0, 0, 0), (0, 1.0, 0), (0, 0, 1.0))
    travel: float = 0.015
    """Largest plate displacement from nominal in any direction [m]."""

    def region(self, plate: BaseplateConfig, above: float = 0.0) -> BoxRegion:
        """Base-frame box holding the plate's top face (raised by `above`), with the travel
        and a few degrees of tilt as slack."""
        half = np.array([plate.cols * plate.pitch / 2 + plate.margin,
                         plate.rows * plate.pitch / 2 + plate.margin, 0.0])
        rot = np.asarray(self.rotation)
        top = np.asarray(self.origin) + rot[:, 2] * (plate.thickness + above)
        extent = np.abs(rot) @ half + self.travel + 0.1 * half.max()
        return BoxRegion(tuple(top - extent), tuple(top + extent))


def plate_layout(cfg: SceneConfig = NOMINAL_CELL, travel: float = 0.015) -> PlateLayout:
    """Nominal plate frame from the cell layout: Stewart base + home height + platform disc."""
    x, y, z = cfg.stewart_base
    return PlateLayout((x, y, z + cfg.stewart.home_z + cfg.stewart.platform_thickness), travel=travel)


def plate_in_view(layout: PlateLayout, plate: BaseplateConfig, base_T_plate: Vec, holes_in_plate: Vec,
                  cameras: tuple[CameraModel, ...], above: float, margin: float = 0.02) -> bool:
    """Whether :func:`serpar.vision.plate.locate_holes` can see every hole of the plate at
    `base_T_plate` (4x4, plate frame in the base frame): each hole entry (`holes_in_plate`,
    (N, 3) in the plate frame), and the top of a part seated in it (`above` higher), inside the
    layout's search regions and inside every camera's image by `margin` of the image width.
    A plate the platform has carried to present a far hole can fail this."""
    rot, t = base_T_plate[:3, :3], base_T_plate[:3, 3]
    entries = np.asarray(holes_in_plate) @ rot.T + t
    tops = entries + above * rot[:, 2]
    if not (layout.region(plate).contains(entries).all()
            and layout.region(plate, above=above).contains(tops).all()):
        return False
    for cam in cameras:
        uv = cam.project(np.r_[entries, tops])
        pad = margin * cam.size[0]
        if not np.all((uv > pad) & (uv < np.asarray(cam.size) - pad)):
            return False
    return True
