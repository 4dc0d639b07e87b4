"""Step 1: find the conductors standing in the tray, from the top stereo pair's pixels.

The brass top faces (Ø5 mm, ~25 px across at full resolution) are found by colour (brass
chroma against the blue tray or the grey plate), separated from the darker brass sides by
brightness, and located by a soft-weighted centroid. Left and right detections are matched
with the epipolar constraint inside a region of interest in the base frame (the tray's
nominal box from the cell layout, which also keeps out the parts already on the baseplate)
and triangulated. Upright parts in one tray have their tops on one plane; its height is fitted
to all of them and every top is put on it, which averages the depth noise of the single
triangulations (stereo depth is the weak direction: ~1.1 mm per pixel of disparity here).

The generic pieces (region of interest, brass-top detection, soft centroid, stereo matching)
are shared with :mod:`serpar.vision.plate`. Nothing here reads simulator state.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from serpar.sim.conductor import ConductorConfig
from serpar.sim.scene import SceneConfig
from serpar.sim.tolerances import BODY_H6
from serpar.vision.camera import CameraModel, StereoPair
from serpar.vision.errors import ConductorNotInView
from serpar.vision.layout import BoxRegion

Vec = NDArray[np.float64]
BODY_DIAMETER = BODY_H6.nominal
"""Nominal conductor body diameter [m] (seed 000 Table 1; sim/tolerances.py holds it)."""
NOMINAL_CELL = SceneConfig()
NOMINAL_CONDUCTOR = ConductorConfig()


def grey(image: np.ndarray) -> NDArray[np.float32]:
    """Mean of the colour channels as float32 (less noise than one channel)."""
    return image.astype(np.float32).mean(axis=2) if image.ndim == 3 else image.astype(np.float32)


def expected_diameter_px(camera: CameraModel, region: BoxRegion, diameter: float) -> float:
    """Pixel diameter of a disc of `diameter` at the region's centre depth."""
    centre = (np.asarray(region.low) + np.asarray(region.high)) / 2
    depth = float(camera.to_camera(centre)[0, 2])
    return diameter * float(camera.K[0, 0]) / depth


def soft_centroid(weight: NDArray[np.float32], centre: Vec, radius: float,
                   iterations: int = 3) -> tuple[Vec, float]:
    """Centroid of `weight` in a disc of `radius` around `centre`, re-centred `iterations`
    times; returns (centre, total weight)."""
    h, w = weight.shape
    c, total = np.asarray(centre, dtype=float), 0.0
    for _ in range(iterations):
        x0, y0 = max(0, int(c[0] - radius - 1)), max(0, int(c[1] - radius - 1))
        x1, y1 = min(w, int(c[0] + radius + 3)), min(h, int(c[1] + radius + 3))
        yy, xx = np.mgrid[y0:y1, x0:x1]
        wt = weight[y0:y1, x0:x1] * (((xx - c[0]) ** 2 + (yy - c[1]) ** 2) <= radius**2)
        total = float(wt.sum())
        if total <= 0:
            break
        c = np.array([(wt * xx).sum() / total, (wt * yy).sum() / total])
    return c, total


@dataclass(frozen=True)
class BrassConfig:
    """Thresholds of the brass-top detector (fractions, not grey levels: robust to exposure)."""

    chroma_low: float = 0.2
    """(R - B) / R below this is not brass (grey plate: ~0, blue tray: < 0)."""
    chroma_high: float = 0.45
    """... and counts fully from here (brass: ~0.6-0.7)."""
    top_low: float = 0.6
    top_high: float = 0.9
    """Brightness relative to the blob's top level: the sides are at ~0.3-0.4, the top at 1."""
    min_area: float = 0.35
    max_area: float = 3.0
    """Brass blob area relative to the expected top-face area."""


def find_brass_tops(image: np.ndarray, window: tuple[int, int, int, int], diameter_px: float,
                    config: BrassConfig = BrassConfig()) -> Vec:
    """Sub-pixel centres (N, 2) of brass top faces (bright brass discs) inside `window`."""
    x0, y0, x1, y1 = window
    if x1 - x0 < 4 or y1 - y0 < 4 or image.ndim != 3:
        return np.zeros((0, 2))
    rgb = image[y0:y1, x0:x1].astype(np.float32)
    r, b = rgb[..., 0], rgb[..., 2]
    chroma = (r - b) / np.maximum(r, 1.0)
    brass = np.clip((chroma - config.chroma_low) / (config.chroma_high - config.chroma_low), 0, 1)
    lum = rgb.mean(axis=2)
    mask = ((brass > 0.5) & (lum > 30)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    area = np.pi / 4 * diameter_px**2
    out = []
    for i in range(1, n):
        if not config.min_area * area <= stats[i, cv2.CC_STAT_AREA] <= config.max_area * area:
            continue
        level = float(np.percentile(lum[labels == i], 90))
        top = brass * np.clip((lum / level - config.top_low) / (config.top_high - config.top_low), 0, 1)
        blob = (labels == i)
        seed = np.argwhere(blob & (top > 0.5))
        if len(seed) < 0.3 * area:
            continue
        start = seed[:, ::-1].mean(axis=0)
        centre, total = soft_centroid(np.where(cv2.dilate(blob.astype(np.uint8), None) > 0, top, 0),
                                       start, 0.75 * diameter_px)
        if total > 0.5 * area:
            out.append(centre + (x0, y0))
    return np.array(out).reshape(-1, 2)


def match_stereo(pair: StereoPair, uv_left: Vec, uv_right: Vec, region: BoxRegion,
                 max_px: float) -> tuple[NDArray[np.int_], NDArray[np.int_], Vec]:
    """One-to-one matches between left and right detections whose triangulated point lies in
    `region` with a reprojection error (epipolar consistency) below `max_px`; the assignment
    minimises the summed reprojection error. Returns (left indices, right indices, points)."""
    if len(uv_left) == 0 or len(uv_right) == 0:
        return np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3))
    ii, jj = np.meshgrid(np.arange(len(uv_left)), np.arange(len(uv_right)), indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    pts = pair.triangulate(uv_left[ii], uv_right[jj])
    err = pair.reprojection_error(pts, uv_left[ii], uv_right[jj])
    ok = region.contains(pts) & (err < max_px)
    big = 1e6
    cost = np.where(ok, err, big).reshape(len(uv_left), len(uv_right))
    rows, cols = linear_sum_assignment(cost)
    keep = cost[rows, cols] < big
    rows, cols = rows[keep], cols[keep]
    return rows, cols, pts.reshape(len(uv_left), len(uv_right), 3)[rows, cols]


@dataclass(frozen=True)
class ConductorSighting:
    """One conductor standing in the tray, measured from the stereo pair (base frame) [m]."""

    top: Vec
    """Centre of the top face, on the fitted plane of all tops."""
    axis: Vec
    """Unit axis, up (the tray plane's normal)."""
    shoulder: Vec
    """Axis point where the journal meets the body: top - body_length * axis (grasp reference)."""
    raw_top: Vec
    """The top as triangulated from this part's two detections alone."""
    uv_left: Vec
    uv_right: Vec
    reprojection_px: float
    pocket: int | None
    """Nearest tray pocket of the nominal layout (row-major), None when none is within 3 mm."""


def fit_plane(points: Vec, up: Vec) -> tuple[Vec, Vec]:
    """(point, unit normal towards `up`) of the least-squares plane through `points`."""
    c = points.mean(axis=0)
    n = np.linalg.svd(points - c)[2][-1]
    return c, n if n @ up > 0 else -n


@dataclass(frozen=True)
class TrayVisionConfig:
    max_epipolar_px: float = 1.5
    plane_tolerance: float = 1e-3
    """Tops further than this from the common plane (a lifted or tilted part) do not set it [m]."""
    brass: BrassConfig = field(default_factory=BrassConfig)


UP = (0.0, 0.0, 1.0)


def locate_conductors(pair: StereoPair, left: np.ndarray, right: np.ndarray, tray_region: BoxRegion,
                      conductor: ConductorConfig = NOMINAL_CONDUCTOR, *,
                      normal: tuple[float, float, float] | None = UP, pockets: Vec | None = None,
                      config: TrayVisionConfig = TrayVisionConfig()) -> list[ConductorSighting]:
    """Every conductor standing in `tray_region` (base-frame box from the cell layout).

    Upright parts in one tray have their tops on one plane: its height (and, with
    `normal=None`, its tilt) is fitted to all tops, and each top is then placed on it where its
    two viewing rays meet it, which averages the depth noise of single triangulations. `normal`
    is the tray's nominal normal (cell layout: mounted level); `pockets` (nominal pocket
    centres, :func:`tray_pockets`) only name the pocket of each part. Sorted by pocket, else
    by x then y. Raises ImageError for a wrong image, ConductorNotInView when none is found.
    """
    pair.left.check_image(left)
    pair.right.check_image(right)
    dets = []
    for cam, img in ((pair.left, left), (pair.right, right)):
        d_px = expected_diameter_px(cam, tray_region, BODY_DIAMETER)
        dets.append(find_brass_tops(img, tray_region.pixel_window(cam), d_px, config.brass))
    li, ri, pts = match_stereo(pair, dets[0], dets[1], tray_region, config.max_epipolar_px)
    if len(li) == 0:
        raise ConductorNotInView(f"no conductor top in the tray region {tray_region} "
                                 f"({len(dets[0])} left, {len(dets[1])} right detections)")
    uv_l, uv_r = dets[0][li], dets[1][ri]
    up = np.asarray(UP if normal is None else normal, dtype=float)
    up /= np.linalg.norm(up)
    origin, axis = _tops_plane(pts, up, fit_tilt=normal is None, tol=config.plane_tolerance)
    tops = np.array([_on_plane(pair, a, b, origin, axis) for a, b in zip(uv_l, uv_r)])
    out = []
    for k in range(len(pts)):
        pocket = None
        if pockets is not None:
            dist = np.linalg.norm(np.asarray(pockets) - tops[k, :2], axis=1)
            pocket = int(dist.argmin()) if dist.min() < 3e-3 else None
        err = float(pair.reprojection_error(tops[k:k + 1], uv_l[k:k + 1], uv_r[k:k + 1])[0])
        out.append(ConductorSighting(tops[k], axis.copy(), tops[k] - conductor.body_length * axis,
                                     pts[k], uv_l[k], uv_r[k], err, pocket))
    out.sort(key=lambda s: (s.pocket if s.pocket is not None else 10**6, s.top[0], s.top[1]))
    return out


def _tops_plane(pts: Vec, up: Vec, fit_tilt: bool, tol: float) -> tuple[Vec, Vec]:
    """Plane (point, normal) of the tops: normal `up` and the median height, or (`fit_tilt`,
    three or more spread tops) the least-squares plane; refitted without the outliers."""
    tilt = fit_tilt and len(pts) >= 3 and np.linalg.svd(pts - pts.mean(axis=0))[1][1] > 2e-3
    origin, axis = fit_plane(pts, up) if tilt else (up * np.median(pts @ up), up)
    good = np.abs((pts - origin) @ axis) < tol
    if good.sum() >= (3 if tilt else 1):
        origin, axis = fit_plane(pts[good], up) if tilt else (up * np.mean(pts[good] @ up), up)
    return origin, axis


def _on_plane(pair: StereoPair, uv_l: Vec, uv_r: Vec, origin: Vec, normal: Vec) -> Vec:
    """Point on the plane (origin, normal) whose projections best fit both pixels: the mean of
    the two rays' intersections with the plane (each image gives the lateral position)."""
    hits = []
    for cam, uv in ((pair.left, uv_l), (pair.right, uv_r)):
        ray = cam.rays(uv[None])[0]
        t = (origin - cam.pos) @ normal / (ray @ normal)
        hits.append(cam.pos + t * ray)
    return np.mean(hits, axis=0)
