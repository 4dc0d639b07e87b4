"""Step-2 detectors: dark hole discs with sub-pixel centres, and the plate's straight top edges,
in one image. :mod:`serpar.vision.plate` matches and fits what these find."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from serpar.vision.camera import CameraModel
from serpar.vision.tray_conductors import BrassConfig, grey, soft_centroid

Vec = NDArray[np.float64]


@dataclass(frozen=True)
class PlateVisionConfig:
    """Detector and fit settings. Darkness is relative to the local plate brightness."""

    dark_core: float = 0.5
    """A hole's core is darker than this fraction of the surrounding plate..."""
    min_levels: float = 25.0
    """... and by at least this many grey levels (also the least contrast of a used edge)."""
    weight_low: float = 0.06
    weight_high: float = 0.25
    """Darkness ramp of the centroid weights: the entry chamfer (~0.3) counts fully, the plate
    noise (~0.015 at 250 grey levels) not at all."""
    ring_max: float = 0.12
    """Mean darkness allowed in the ring around a hole (rejects edges, shadows, speckle)."""
    max_epipolar_px: float = 1.5
    hole_sigma_px: float = 0.05
    top_sigma_px: float = 0.3
    edge_sigma_px: float = 0.15
    """Expected noise of one hole centre, one brass top, one edge sample [px]."""
    edge_margin: float = 0.004
    """Edge samples stay this far from the plate corners [m]."""
    min_edge_samples: int = 20
    min_holes: int = 8
    max_rms_px: float = 1.0
    """Largest RMS reprojection error of an accepted fit, at full resolution [px]."""
    brass: BrassConfig = field(default_factory=BrassConfig)


def find_dark_discs(image: np.ndarray, window: tuple[int, int, int, int], diameter_px: float,
                    config: PlateVisionConfig = PlateVisionConfig()) -> Vec:
    """Sub-pixel centres (N, 2) of isolated dark discs of about `diameter_px` in `window`:
    soft-weighted darkness centroids against the local median plate level."""
    x0, y0, x1, y1 = window
    if x1 - x0 < 8 or y1 - y0 < 8:
        return np.zeros((0, 2))
    g = grey(image[y0:y1, x0:x1])
    k = max(5, int(2 * round(1.3 * diameter_px) + 1))
    background = cv2.medianBlur(np.clip(g, 0, 255).astype(np.uint8), k).astype(np.float32)
    dark = (background - g) / np.maximum(background, 1.0)
    core = ((dark > config.dark_core) & (background - g > config.min_levels)).astype(np.uint8)
    n, _, stats, cents = cv2.connectedComponentsWithStats(core, connectivity=8)
    area = np.pi / 4 * diameter_px**2
    weight = np.clip((dark - config.weight_low) / (config.weight_high - config.weight_low), 0, 1)
    out = []
    for i in range(1, n):
        w, h, a = stats[i, cv2.CC_STAT_WIDTH], stats[i, cv2.CC_STAT_HEIGHT], stats[i, cv2.CC_STAT_AREA]
        if not (0.2 * area <= a <= 1.5 * area and max(w, h) <= 1.6 * diameter_px):
            continue
        centre, total = soft_centroid(weight, cents[i], 0.9 * diameter_px)
        # The ring around a hole must be plate: no edge, shadow or speckle patch.
        r, (cx, cy) = int(1.4 * diameter_px), np.round(centre).astype(int)
        # Clipped to the window: a hole near its border has a partial ring.
        ys = slice(max(0, cy - r), min(dark.shape[0], cy + r + 1))
        xs = slice(max(0, cx - r), min(dark.shape[1], cx + r + 1))
        yy, xx = np.mgrid[ys, xs]
        r2 = (xx - centre[0]) ** 2 + (yy - centre[1]) ** 2
        ring = (r2 > (0.8 * diameter_px) ** 2) & (r2 < (1.3 * diameter_px) ** 2)
        if 0.5 * area < total < 1.6 * area and ring.any() and dark[ys, xs][ring].mean() <= config.ring_max:
            out.append(centre + (x0, y0))
    return np.array(out).reshape(-1, 2)


def measure_edge(grey_image: NDArray[np.float32], camera: CameraModel, a: Vec, b: Vec, inside: Vec,
                 config: PlateVisionConfig = PlateVisionConfig()) -> tuple[Vec, Vec, Vec]:
    """Sub-pixel points (N, 2) of a straight bright-to-dark edge from base-frame point `a` to
    `b` (`inside` on the bright side) in a grey image, their position t along a -> b and their
    standard uncertainty [px] across the edge.

    Each image row (column, for a flatter line) across the predicted line gives one point.
    The two pixels where the profile crosses halfway between its plateaus hold the edge; the
    bright fraction they cover, measured between the plate level and the pixel just beyond
    them (what lies right outside the edge: a shadow band, the fixture), places it."""
    g, s = grey_image, camera.size[0] / 2048
    near, far, search = max(2.0, 2.5 * s), max(4.0, 7 * s), max(2.0, 4 * s)
    (ua, va), (ub, vb), (ui, vi) = camera.project(np.array([a, b, inside]))
    rows = abs(vb - va) >= abs(ub - ua)  # scan rows for a steep line, columns otherwise
    if not rows:
        g, (ua, va), (ub, vb), (ui, vi) = g.T, (va, ua), (vb, ub), (vi, ui)
    ks = np.arange(-int(far) - 3, int(far) + 4)
    found = []  # (t, row, base, side, i, profile, bright)
    for row in range(int(np.ceil(min(va, vb))), int(np.floor(max(va, vb))) + 1):
        t = (row - va) / (vb - va)
        line = ua + t * (ub - ua)
        side = 1 if ui + (row - vi) * (ub - ua) / (vb - va) > line else -1
        base = round(line)
        cols = base + side * ks  # walks from outside (dark) to inside (bright)
        if row < 0 or row >= g.shape[0] or min(cols) < 0 or max(cols) >= g.shape[1]:
            continue
        prof, dist = g[row, cols], (cols - line) * side
        bright = np.median(prof[(dist > near) & (dist < far)])
        dark = np.median(prof[(dist < -near) & (dist > -far)])
        if bright - dark < max(config.min_levels, 0.2 * bright):
            continue
        cross = np.flatnonzero((prof[:-1] < (bright + dark) / 2) & (prof[1:] >= (bright + dark) / 2))
        offset = np.abs(ks[cross] + 0.5 - side * (line - base))
        ok = (cross >= 2) & (offset < search)
        cross, offset = cross[ok], offset[ok]
        if len(cross):
            found.append((t, row, base, side, cross[np.argmin(offset)], prof, bright))
    if not found:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    pts, ts, sig = [], [], []
    beyond = np.array([f[5][f[4] - 1] for f in found], dtype=float)
    for j, (t, row, base, side, i, prof, bright) in enumerate(found):
        e = i + 1 if prof[i + 1] < bright - 0.1 * (bright - prof[i]) else i  # the mixed pixel
        out = prof[e - 1]  # what lies right beyond the edge: a shadow band, fixture, side face
        cover = np.clip((prof[e:e + 2] - out) / max(bright - out, 1.0), 0.0, 1.0)
        pos = base + side * (ks[e] + 1.5 - cover.sum())
        # Uncertainty: anti-aliasing steps (~0.1 px) and how well one pixel gives the level
        # beyond (speckle on the fixture alternates from pixel to pixel and row to row).
        spread = np.std(beyond[max(0, j - 4):j + 5]) + abs(prof[e - 1] - prof[e - 2]) / 2
        pts.append((pos, row) if rows else (row, pos))
        ts.append(t)
        sig.append(np.hypot(config.edge_sigma_px, spread * (2 - cover.sum()) / max(bright - out, 1.0)))
    return np.array(pts).reshape(-1, 2), np.array(ts), np.array(sig)
