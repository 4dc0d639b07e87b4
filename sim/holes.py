"""Round holes that stay round at the micrometre scale, built from boxes.

MuJoCo convexifies meshes, so a mesh hole closes up. Instead each bore is a
ring of N boxes whose inner faces are tangent to the bore circle. The free
region is then the regular N-gon of inradius R; a journal of radius r in it can
move (R - r) towards a face and (R - r) / cos(pi / N) towards a vertex, so the
hole deviates from round by (R - r) * (1 / cos(pi / N) - 1) where the journal
can touch it (< 0.1 um for N = 24 and the largest H7/h6 clearance). Faces are
wider than the polygon sides: an edge of a convex polygon extended past its
vertex lies outside the polygon, so the overlap never narrows the bore.

An optional 45 deg entry chamfer is a second ring of boxes tilted 45 deg, and a
third ring forms the top face between the chamfer and the surrounding plate.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from sim.errors import ConfigError

GeomHook = Callable[[mujoco.MjsGeom], None]


@dataclass(frozen=True)
class BoreGeometry:
    """Shape of one faceted bore [m]."""

    diameter: float
    depth: float
    chamfer: float
    n_facets: int
    outer_radius: float
    """Radius out to which the ring boxes cover the annulus (meets the surrounding plate)."""

    def __post_init__(self) -> None:
        if self.n_facets < 6:
            raise ConfigError(f"n_facets={self.n_facets}: need at least 6 facets per bore")
        if self.chamfer < 0 or self.chamfer >= self.depth:
            raise ConfigError(f"chamfer {self.chamfer} m must be in [0, depth={self.depth})")
        if self.outer_radius * math.cos(math.pi / self.n_facets) <= self.diameter / 2 + self.chamfer:
            raise ConfigError("outer_radius too small to surround the bore and its chamfer")

    def roundness_error(self, journal_diameter: float) -> float:
        """Largest deviation [m] of the free region from a round hole for this journal."""
        gap = max(0.0, (self.diameter - journal_diameter) / 2)
        return gap * (1.0 / math.cos(math.pi / self.n_facets) - 1.0)


def grid_centres(rows: int, cols: int, pitch: float) -> np.ndarray:
    """(rows, cols, 2) centres of a grid centred on the origin, row-major from the -x, -y corner."""
    xs = (np.arange(cols) - (cols - 1) / 2) * pitch
    ys = (np.arange(rows) - (rows - 1) / 2) * pitch
    return np.stack(np.meshgrid(xs, ys), axis=-1)


def _quat_z(theta: float) -> np.ndarray:
    return np.array([math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


_QUAT_Y45 = np.array([math.cos(math.pi / 8), 0.0, math.sin(math.pi / 8), 0.0])


def add_bore(
    body: mujoco.MjsBody,
    centre: tuple[float, float],
    top_z: float,
    geometry: BoreGeometry,
    setup: GeomHook,
) -> int:
    """Add the boxes of one bore (axis +z, entry at top_z) to `body`; returns the geom count.

    `setup` is called on every new geom (contact parameters, material, groups).
    """
    g = geometry
    radius, c, n = g.diameter / 2, g.chamfer, g.n_facets
    half_angle = math.pi / n
    width = g.outer_radius * math.tan(half_angle)  # tangential half-width: covers the annulus
    bottom_z = top_z - g.depth
    count = 0

    def box(theta: float, radial: float, z: float, size: tuple[float, float, float], quat) -> None:
        nonlocal count
        geom = body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(size),
            pos=[centre[0] + radial * math.cos(theta), centre[1] + radial * math.sin(theta), z],
            quat=list(quat),
        )
        setup(geom)
        count += 1

    for k in range(n):
        theta = 2 * math.pi * k / n
        qz = _quat_z(theta)
        # Bore wall: inner face tangent to the circle of radius R, below the chamfer.
        hx, hz = (g.outer_radius - radius) / 2, (g.depth - c) / 2
        box(theta, radius + hx, bottom_z + hz, (hx, width, hz), qz)
        if c <= 0:
            continue
        # Top ring between chamfer edge (R + c) and the plate.
        hx_top = (g.outer_radius - radius - c) / 2
        box(theta, radius + c + hx_top, top_z - c / 2, (hx_top, width, c / 2), qz)
        # Chamfer: a box tilted 45 deg whose inner face spans exactly (R, top-c)..(R+c, top);
        # its body lies behind the face, inside the wall and top boxes.
        t = c
        face_mid_r, face_mid_z = radius + c / 2, top_z - c / 2
        off = t / 2 / math.sqrt(2)
        box(
            theta,
            face_mid_r + off,
            face_mid_z - off,
            (t / 2, (radius + 2 * c) * math.tan(half_angle) * 1.05, c * math.sqrt(2) / 2),
            _quat_mul(qz, _QUAT_Y45),
        )
    return count


def add_grid_plate(
    body: mujoco.MjsBody,
    centres: np.ndarray,
    pitch: float,
    thickness: float,
    margin: float,
    window: float,
    setup: GeomHook,
) -> int:
    """Plate around a rectangular hole grid: bars that leave a square window per hole.

    The window (half-size `window`) is filled by the bore's ring boxes. Plate bottom at
    z = 0, top at z = thickness. `centres` is (rows, cols, 2). Returns the geom count.
    """
    rows, cols = centres.shape[:2]
    xs, ys = centres[0, :, 0], centres[:, 0, 1]
    x_lo, x_hi = xs.min() - pitch / 2 - margin, xs.max() + pitch / 2 + margin
    y_lo, y_hi = ys.min() - pitch / 2 - margin, ys.max() + pitch / 2 + margin
    count = 0

    def bar(x0: float, x1: float, y0: float, y1: float) -> None:
        nonlocal count
        if x1 - x0 <= 0 or y1 - y0 <= 0:
            return
        geom = body.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[(x1 - x0) / 2, (y1 - y0) / 2, thickness / 2],
            pos=[(x0 + x1) / 2, (y0 + y1) / 2, thickness / 2],
        )
        setup(geom)
        count += 1

    y_edges = [y_lo] + [y for yc in ys for y in (yc - window, yc + window)] + [y_hi]
    for y0, y1 in zip(y_edges[0::2], y_edges[1::2]):  # full-width strips between hole rows
        bar(x_lo, x_hi, y0, y1)
    x_edges = [x_lo] + [x for xc in xs for x in (xc - window, xc + window)] + [x_hi]
    for yc in ys:  # short bars between holes of one row
        for x0, x1 in zip(x_edges[0::2], x_edges[1::2]):
            bar(x0, x1, yc - window, yc + window)
    return count
