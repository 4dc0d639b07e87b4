"""Step 2: find the baseplate's holes, empty or occupied, from the top stereo pair's pixels.

Empty holes are dark discs on the bright plate face (through-bores onto a black fixture),
located by a soft-weighted darkness centroid against the local median plate level, so the
detector follows the plate's brightness. Occupied holes show a conductor's brass top one body
length above the plate. Detections are matched left-right by the epipolar constraint inside
the plate's region of interest, triangulated, and given design grid indices (the grid's
orientation is known to a few degrees, its position is not). The 6-DoF plate pose is then
fitted to every observation at once by minimising the reprojection error in both images
(scipy least_squares, soft-L1 loss), which averages the per-hole noise.

Depth is the weak direction (~0.9 mm per pixel of disparity) and a bore does not look the
same from the two cameras: the chamfer and bore wall are seen at different angles and lit by
each camera's own headlight, so the hole centroids carry a few hundredths of a pixel of bias
along the baseline (~0.07 mm of depth, measured). The plate's outer top edges that cross the
baseline are fitted too: they look alike from both cameras, and their anti-aliasing and
speckle errors are independent of the holes', so the joint fit roughly halves the depth error.
Nothing here reads simulator state.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from serpar.sim.baseplate import BaseplateConfig
from serpar.sim.conductor import ConductorConfig
from serpar.sim.scene import SceneConfig
from serpar.sim.tolerances import HOLE_H7
from serpar.vision.camera import StereoPair
from serpar.vision.errors import HoleNotVisible, PlateNotFound
from serpar.vision.layout import BoxRegion, PlateLayout, plate_layout
from serpar.vision.plate_detect import PlateVisionConfig, find_dark_discs, measure_edge
from serpar.vision.plate_grid import assign_grid, on_plane
from serpar.vision.tray_conductors import (
    BODY_DIAMETER,
    expected_diameter_px,
    find_brass_tops,
    grey,
    match_stereo,
)

Vec = NDArray[np.float64]
DEFAULT_CONFIG = PlateVisionConfig()
HoleStatus = Literal["empty", "occupied", "unseen"]
NOMINAL_CELL = SceneConfig()
NOMINAL_PLATE = BaseplateConfig()
NOMINAL_CONDUCTOR = ConductorConfig()


@dataclass(frozen=True)
class HoleResult:
    """One hole as measured. Positions in the base frame [m]."""

    index: int
    status: HoleStatus
    centre: Vec
    """Entry centre on the plate's top face, from the fitted plate pose (predicted if unseen)."""
    axis: Vec
    """Unit hole axis out of the hole (the fitted plate normal)."""
    raw: Vec | None
    """Triangulated from this hole's own two detections (occupied: the top, less one body
    length along the axis); None if unseen. Carries the detections' depth bias."""
    uv_left: Vec | None
    uv_right: Vec | None
    reason: str = ""
    """Why an unseen hole is unseen."""


@dataclass(frozen=True)
class PlateMeasurement:
    """Result of :func:`locate_holes`: the fitted plate pose and every hole."""

    rotation: Vec
    """Plate frame axes (columns) in the base frame."""
    origin: Vec
    """Plate frame origin (bottom-face centre, as :mod:`serpar.sim.baseplate`) in the base frame [m]."""
    holes: tuple[HoleResult, ...]
    rms_px: float
    """RMS reprojection error of the fit (holes, tops, edges) [px at the images' size]."""
    edge_samples: int
    """Plate-edge samples used in the fit (0: depth from the holes alone, ~0.07 mm biased)."""

    def hole(self, k: int) -> HoleResult:
        """Hole k; HoleNotVisible when it is not seen in both cameras (or does not exist)."""
        if not 0 <= k < len(self.holes):
            raise HoleNotVisible(k, f"no such hole; valid 0..{len(self.holes) - 1}")
        if self.holes[k].status == "unseen":
            raise HoleNotVisible(k, self.holes[k].reason)
        return self.holes[k]

    def indices(self, status: HoleStatus) -> list[int]:
        return [h.index for h in self.holes if h.status == status]

    @property
    def normal(self) -> Vec:
        return self.rotation[:, 2]


def _model_points(plate: BaseplateConfig, height: float) -> Vec:
    xy = plate.hole_centres().reshape(-1, 2)
    return np.c_[xy, np.full(len(xy), height)]


def _kabsch(model: Vec, measured: Vec) -> tuple[Vec, Vec]:
    """(R, t) with measured ~ R model + t (least squares)."""
    cm, cd = model.mean(axis=0), measured.mean(axis=0)
    u, _, vt = np.linalg.svd((model - cm).T @ (measured - cd))
    rot = vt.T @ np.diag([1, 1, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
    return rot, cd - rot @ cm


@dataclass(frozen=True)
class _Obs:
    """Observations for the pose fit, one per image point: model points in the plate frame."""

    points: Vec
    cam: NDArray[np.int_]
    """0 = left, 1 = right image."""
    uv: Vec
    sigma: Vec
    normal: Vec
    """Image normal of an edge sample (its residual is along it); zeros for points."""

    @staticmethod
    def stack(*parts: _Obs) -> _Obs:
        return _Obs(*(np.concatenate([getattr(p, f) for p in parts])
                      for f in ("points", "cam", "uv", "sigma", "normal")))


def _fit_pose(pair: StereoPair, obs: _Obs, rot0: Vec, t0: Vec) -> tuple[Vec, Vec, float]:
    """Plate pose minimising the weighted reprojection error; returns (rot, t, RMS px)."""
    cams, edge = (pair.left, pair.right), np.any(obs.normal != 0, axis=1)

    def predict(x: Vec) -> Vec:
        pts = Rotation.from_rotvec(x[:3]).apply(obs.points) + x[3:]
        uv = np.zeros_like(obs.uv)
        for c in (0, 1):
            uv[obs.cam == c] = cams[c].project(pts[obs.cam == c])
        return uv

    def residual(x: Vec) -> Vec:
        d = (predict(x) - obs.uv) / obs.sigma[:, None]
        return np.r_[d[~edge].ravel(), np.sum(d[edge] * obs.normal[edge], axis=1)]

    x0 = np.r_[Rotation.from_matrix(rot0).as_rotvec(), t0]
    sol = least_squares(residual, x0, loss="soft_l1", f_scale=3.0, x_scale=np.r_[[1e-3] * 3, [1e-4] * 3])
    d = predict(sol.x) - obs.uv
    err = np.r_[np.linalg.norm(d[~edge], axis=1), np.abs(np.sum(d[edge] * obs.normal[edge], axis=1))]
    return Rotation.from_rotvec(sol.x[:3]).as_matrix(), sol.x[3:], float(np.sqrt(np.mean(err**2)))


def _edge_obs(pair: StereoPair, greys: list[NDArray[np.float32]], plate: BaseplateConfig,
              rot: Vec, t: Vec, config: PlateVisionConfig) -> _Obs:
    """Samples of the plate's outer top edges that cross the baseline in each image (the
    ones that carry depth; edges along the baseline would only add their scale errors)."""
    hx = plate.cols * plate.pitch / 2 + plate.margin
    hy = plate.rows * plate.pitch / 2 + plate.margin
    z = plate.thickness
    m = config.edge_margin
    sides = [((-hx + m, s * hy, z), (hx - m, s * hy, z)) for s in (-1, 1)]
    sides += [((s * hx, -hy + m, z), (s * hx, hy - m, z)) for s in (-1, 1)]
    inside = t + rot @ np.array([0, 0, z])
    baseline = (pair.right.pos - pair.left.pos) / pair.baseline
    parts = [_Obs(np.zeros((0, 3)), np.zeros(0, int), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2)))]
    for c, cam in enumerate((pair.left, pair.right)):
        along = np.diff(cam.project(np.array([inside, inside + 1e-3 * baseline])), axis=0)[0]
        for a, b in sides:
            a, b = np.asarray(a, float), np.asarray(b, float)
            wa, wb = rot @ a + t, rot @ b + t
            d = np.diff(cam.project(np.array([wa, wb])), axis=0)[0]
            nrm = np.array([-d[1], d[0]]) / np.linalg.norm(d)
            if abs(nrm @ along) < 0.7 * np.linalg.norm(along):
                continue
            uv, ts, sig = measure_edge(greys[c], cam, wa, wb, inside, config)
            if len(uv) >= config.min_edge_samples:
                parts.append(_Obs(a + ts[:, None] * (b - a), np.full(len(uv), c), uv, sig,
                                  np.tile(nrm, (len(uv), 1))))
    return _Obs.stack(*parts)


def locate_holes(pair: StereoPair, left: np.ndarray, right: np.ndarray,
                 plate: BaseplateConfig = NOMINAL_PLATE,
                 conductor: ConductorConfig = NOMINAL_CONDUCTOR,
                 layout: PlateLayout | None = None,
                 config: PlateVisionConfig = DEFAULT_CONFIG) -> PlateMeasurement:
    """Every hole of the plate: entry centre, axis and empty/occupied/unseen, from two images.

    `layout` (default: the cell's) bounds where the plate may be and gives its nominal
    orientation. Raises ImageError (wrong image) or PlateNotFound (grid not recovered, or the
    detections do not fit the design).
    """
    pair.left.check_image(left)
    pair.right.check_image(right)
    layout = layout or plate_layout()
    rot_nominal = np.asarray(layout.rotation, dtype=float)
    region_hole = layout.region(plate)
    region_top = layout.region(plate, above=conductor.body_length)
    union = BoxRegion(tuple(np.minimum(region_hole.low, region_top.low)),
                      tuple(np.maximum(region_hole.high, region_top.high)))
    entry = plate.bore(HOLE_H7.nominal).diameter + 2 * plate.chamfer
    holes_uv, tops_uv, greys = [], [], []
    for cam, img in ((pair.left, left), (pair.right, right)):
        window = union.pixel_window(cam)
        greys.append(grey(img))
        holes_uv.append(find_dark_discs(img, window, expected_diameter_px(cam, region_hole, entry), config))
        tops_uv.append(find_brass_tops(img, window, expected_diameter_px(cam, region_top, BODY_DIAMETER),
                                       config.brass))
    hl, hr, hp = match_stereo(pair, holes_uv[0], holes_uv[1], region_hole, config.max_epipolar_px)
    tl, tr, tp = match_stereo(pair, tops_uv[0], tops_uv[1], region_top, 3 * config.max_epipolar_px)
    # A seated top, taken down one body length, lies on the entries' plane: every hole, empty
    # or filled, places the plate (a nearly full plate has only a few empty ones left).
    up = rot_nominal[:, 2]
    entries = np.r_[hp, tp - conductor.body_length * up]
    if len(entries) < config.min_holes:
        raise PlateNotFound(f"{len(entries)} holes matched in both images, {len(hp)} empty and "
                            f"{len(tp)} filled (need {config.min_holes}); {len(holes_uv[0])} + "
                            f"{len(tops_uv[0])} left and {len(holes_uv[1])} + {len(tops_uv[1])} "
                            "right detections")
    keep, normal = on_plane(entries, up)
    kh, kt = keep[:len(hp)], keep[len(hp):]
    hl, hr, hp, tl, tr, tp = hl[kh], hr[kh], hp[kh], tl[kt], tr[kt], tp[kt]
    k = assign_grid(np.r_[hp, tp - conductor.body_length * normal], plate, rot_nominal)
    kind = np.r_[np.zeros(len(hp), int), np.ones(len(tp), int)]  # 0 empty, 1 occupied
    uv_l, uv_r = np.r_[holes_uv[0][hl], tops_uv[0][tl]], np.r_[holes_uv[1][hr], tops_uv[1][tr]]
    use = k >= 0
    model = np.c_[plate.hole_centres().reshape(-1, 2)[k[use]],
                  plate.thickness + kind[use] * conductor.body_length]
    sigma = np.where(kind[use] == 0, config.hole_sigma_px, config.top_sigma_px)
    n = int(use.sum())
    points = _Obs(np.r_[model, model], np.r_[np.zeros(n, int), np.ones(n, int)],
                  np.r_[uv_l[use], uv_r[use]], np.r_[sigma, sigma], np.zeros((2 * n, 2)))
    rot, t = _kabsch(model, np.r_[hp, tp][use])
    rot, t, _ = _fit_pose(pair, points, rot, t)
    edges = _edge_obs(pair, greys, plate, rot, t, config)
    rot, t, rms = _fit_pose(pair, _Obs.stack(points, edges), rot, t)
    if rms > config.max_rms_px * pair.left.size[0] / 2048:
        raise PlateNotFound(f"the detections do not fit the design grid (RMS {rms:.2f} px)")
    centres = _model_points(plate, plate.thickness) @ rot.T + t
    raw = np.r_[hp, tp] - np.outer(kind * conductor.body_length, rot[:, 2])
    seen = {int(kk): j for j, kk in enumerate(k) if kk >= 0}
    holes = []
    for h in range(plate.n_holes):
        j = seen.get(h)
        if j is None:
            holes.append(HoleResult(h, "unseen", centres[h], rot[:, 2], None, None, None,
                                    _unseen_reason(pair, centres[h])))
        else:
            holes.append(HoleResult(h, "occupied" if kind[j] else "empty", centres[h], rot[:, 2],
                                    raw[j], uv_l[j], uv_r[j]))
    return PlateMeasurement(rot, t, tuple(holes), rms, len(edges.uv))


def _unseen_reason(pair: StereoPair, centre: Vec) -> str:
    for cam in (pair.left, pair.right):
        u, v = cam.project(centre)[0]
        if not (0 <= u < cam.size[0] and 0 <= v < cam.size[1]):
            return f"outside the image of {cam.name}"
    return "not detected in both images (occluded or covered)"
