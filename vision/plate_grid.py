"""Step 2's hole grid: which design hole each triangulated entry point is, from the points
alone (a lattice of the design pitch fitted in their plane)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from serpar.sim.baseplate import BaseplateConfig
from serpar.vision.errors import PlateNotFound

Vec = NDArray[np.float64]

PLANE_TOL = 1e-3
"""Matched holes farther than this from the plate plane are mismatches or false detections
(the plate is flat to microns; a wrong stereo match lands millimetres off it)."""


STRAY_LINE_MAX = 1
"""Most detections an outer lattice line beyond the design span may hold to be dropped as
false (a real row of 6 holes shows at least 4 with up to 2 hidden or missed)."""


def on_plane(points: Vec, up: Vec) -> tuple[NDArray[np.bool_], Vec]:
    """Inliers of the plane through `points` (refitted without the far ones) and its normal."""
    keep = np.ones(len(points), bool)
    normal = up
    for tol in (4 * PLANE_TOL, 2 * PLANE_TOL, PLANE_TOL):
        if keep.sum() < 3:
            break
        centre = np.median(points[keep], axis=0)
        normal = np.linalg.svd(points[keep] - centre)[2][-1]
        normal = normal if normal @ up > 0 else -normal
        keep = np.abs((points - centre) @ normal) < tol
    return keep, normal


def assign_grid(points: Vec, plate: BaseplateConfig, rot0: Vec) -> NDArray[np.int_]:
    """Hole index (or -1) of each entry point (N, 3): a lattice of the design pitch in the
    fitted plane, its orientation refined from the nominal `rot0`, its origin from the span."""
    centre = points.mean(axis=0)
    normal = np.linalg.svd(points - centre)[2][-1]
    normal = normal if normal @ rot0[:, 2] > 0 else -normal
    ex = rot0[:, 0] - (rot0[:, 0] @ normal) * normal
    ex /= np.linalg.norm(ex)
    xy = np.c_[(points - centre) @ ex, (points - centre) @ np.cross(normal, ex)] / plate.pitch
    diff = (xy[:, None] - xy[None]).reshape(-1, 2)
    near = np.abs(np.linalg.norm(diff, axis=1) - 1) < 0.2
    if near.any():  # neighbour directions, modulo 90 deg
        ang = np.angle(np.mean(np.exp(4j * np.arctan2(diff[near, 1], diff[near, 0])))) / 4
        xy = xy @ np.array([[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]])
    phase = np.angle(np.mean(np.exp(2j * np.pi * xy), axis=0)) / (2 * np.pi)
    ij = np.round(xy - phase).astype(int)
    off = np.linalg.norm(xy - phase - ij, axis=1)
    keep = off <= 0.25
    if keep.sum() < 3:
        raise PlateNotFound("the matched holes do not form a grid of the design pitch")
    keep &= ~_stray_lines(ij, keep, (plate.cols, plate.rows))
    lo, span = ij[keep].min(axis=0), ij[keep].max(axis=0) - ij[keep].min(axis=0) + 1
    if span[0] != plate.cols or span[1] != plate.rows:
        raise PlateNotFound(f"hole grid incomplete or ambiguous: seen {span[0]} x {span[1]} "
                            f"(cols x rows), design {plate.cols} x {plate.rows}")
    k = np.where(keep, (ij[:, 1] - lo[1]) * plate.cols + (ij[:, 0] - lo[0]), -1)
    ks, counts = np.unique(k[k >= 0], return_counts=True)
    for dup in ks[counts > 1]:  # two detections on one lattice site: keep the closer one
        idx = np.flatnonzero(k == dup)
        k[idx[np.argsort(off[idx])[1:]]] = -1
    return k


def _stray_lines(ij: NDArray[np.int_], keep: NDArray[np.bool_], design: tuple[int, int]) -> NDArray[np.bool_]:
    """Detections on outer lattice lines beyond the design's span that hold at most
    STRAY_LINE_MAX of them: a false match on the plate plane just off the grid (seen: a dark
    feature beside a moved plate's corner) would otherwise widen the grid by a line."""
    stray = np.zeros(len(ij), bool)
    for axis, size in enumerate(design):
        while True:
            ok = keep & ~stray
            lo, hi = ij[ok, axis].min(), ij[ok, axis].max()
            if hi - lo + 1 <= size:
                break
            counts = {end: int(np.sum(ok & (ij[:, axis] == end))) for end in (lo, hi)}
            end = min(counts, key=counts.get)
            if counts[end] > STRAY_LINE_MAX:
                break  # a real line of holes: leave the span error to the caller
            stray |= ok & (ij[:, axis] == end)
    return stray
