"""Round holes that stay round at the micrometre scale, built from convex facets.

MuJoCo convexifies meshes, so a mesh hole closes up. Instead each bore is a
ring of N convex wedges whose inner faces are the sides of the regular N-gon
of inradius R. A journal of radius r in it can move (R - r) towards a face and
(R - r) / cos(pi / N) towards a vertex, so the hole deviates from round by
(R - r) * (1 / cos(pi / N) - 1) where the journal can touch it (0.16 um for
N = 16 and the largest H7/h6 clearance). Neighbouring wedges meet on the plane
through the axis and the polygon vertex, so they tile the annulus exactly.

An optional 45 deg entry chamfer is a cut corner of each wedge's section, and
the section's top edge is the plate top between the chamfer and the
surrounding plate: one geom per facet (an earlier build used three boxes per
facet, 1 728 plate geoms whose bounding boxes cost half the step time).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError

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


def _quat_z(theta: float) -> list[float]:
    return [math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)]


def facet_section(geometry: BoreGeometry, top_z: float) -> list[tuple[float, float]]:
    """(radial, z) corners of one facet's cross-section, counter-clockwise: the bore wall from
    the bottom to the chamfer, the 45 deg chamfer, the plate top out to the outer radius. The
    section is convex (a rectangle with one corner cut), so the facet is one convex geom."""
    g = geometry
    radius, c, bottom = g.diameter / 2, g.chamfer, top_z - g.depth
    corners = [(radius, bottom), (g.outer_radius, bottom), (g.outer_radius, top_z)]
    if c > 0:
        return corners + [(radius + c, top_z), (radius, top_z - c)]
    return corners + [(radius, top_z)]


def add_bore(
    spec: mujoco.MjSpec,
    body: mujoco.MjsBody,
    centre: tuple[float, float],
    top_z: float,
    geometry: BoreGeometry,
    setup: GeomHook,
    name: str,
) -> int:
    """Add the facets of one bore (axis +z, entry at top_z) to `body`; returns the geom count.

    Each facet is a convex wedge (mesh `name`, shared by the bore's facets): the section of
    :func:`facet_section` swept over the facet's angle, so neighbouring facets meet on a shared
    plane through the axis without overlapping (overlapping coplanar top faces flicker in
    renders). `setup` is called on every new geom (contact parameters, material)."""
    g = geometry
    tan_half = math.tan(math.pi / g.n_facets)
    section = facet_section(g, 0.0)
    spec.add_mesh(name=name, uservert=[v for r, z in section for y in (-r * tan_half, r * tan_half)
                                       for v in (r, y, z)])
    for k in range(g.n_facets):
        theta = 2 * math.pi * k / g.n_facets
        geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name,
                             pos=[centre[0], centre[1], top_z], quat=_quat_z(theta))
        setup(geom)
    return g.n_facets


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
