"""In-hand inspection (step 4): the grasped conductor's journal axis relative to the gripper,
measured from the two `inspect` images against the backlight.

Per camera, sub-pixel silhouette edges are found row by row: the Ø5 body against the
backlight below the pads and against the dark pads between them, the coaxial Ø1.7 journal
against the backlight. Every edge pixel's viewing ray is tangent to its cylinder, so one
robust least-squares fit over both cameras gives the common axis, both radii (which makes a
symmetric edge bias harmless: the axis plane is the bisector of the tangent planes) and the
offset of edges against the pads. The tip is where the fitted journal's chamfered end
reproduces the lower end of its silhouette.

Inputs are pixels, calibrated cameras and the TCP pose the arm model computes from the
measured joints; nothing here reads simulator state.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from serpar.sim.conductor import ConductorConfig
from serpar.sim.tolerances import BODY_H6, JOURNAL_H6
from serpar.vision.camera import CameraModel, StereoPair
from serpar.vision.inhand_edges import (
    NOMINAL_CONDUCTOR,
    CameraEdges,
    InHandConfig,
    find_edges,
)

Vec = NDArray[np.float64]
DEFAULT_CONFIG = InHandConfig()


@dataclass(frozen=True, eq=False)
class InHandMeasurement:
    """The journal as held, in the TCP frame (x, y lateral; z the approach axis) [m, rad]."""

    tip: Vec
    """Journal tip centre (end face) in the TCP frame."""
    axis: Vec
    """Unit journal axis (body -> tip) in the TCP frame."""
    offset: Vec
    """Lateral offset of the axis at the tip: the tip's (x, y) in the TCP frame."""
    tip_z: float
    """Tip position along the TCP z."""
    tilt: float
    """Angle between the journal axis and the TCP z."""
    tilt_direction: float
    """Where the tip leans: atan2(axis y, axis x) in the TCP frame."""
    tip_base: Vec
    axis_base: Vec
    """Tip centre and unit axis in the base frame."""
    body_diameter: float
    journal_diameter: float
    """Fitted silhouette diameters (a plausibility check against the h6 bands)."""
    rms_px: float
    """RMS tangency residual of the edges used."""
    edges: tuple[CameraEdges, CameraEdges]
    """What was found in the left and right images."""
    inliers: tuple[NDArray[np.bool_], NDArray[np.bool_]]
    """Which of those side edges the final fit used (the rest: pads in front of the body, ...)."""
    conductor: ConductorConfig


@dataclass(frozen=True, eq=False)
class _Rays:
    """One camera's edges as viewing rays, with what each one is tangent to."""

    centre: Vec
    direction: Vec
    part: NDArray[np.int64]
    dark: NDArray[np.bool_]
    weight: Vec
    """Pixels per metre at the part."""


_PRIOR_MM = np.array([0.02, 0.02, 0.01])
"""Spreads of the weak priors on the radii and the dark-edge offset [mm]."""
_X_SCALE = np.array([0.01, 0.01, 1e-4, 1e-4, 0.01, 0.01, 0.003])


def _axis(x: Vec, origin: Vec, rot: Vec) -> tuple[Vec, Vec]:
    """Axis point (in the plane through `origin` normal to the TCP z) and unit direction.

    x = (dx, dy [mm] along TCP x, y; ax, ay [rad]; r_body, r_journal, dark-edge offset [mm]).
    """
    point = origin + 1e-3 * (x[0] * rot[:, 0] + x[1] * rot[:, 1])
    direction = rot[:, 2] + x[2] * rot[:, 0] + x[3] * rot[:, 1]
    return point, direction / np.linalg.norm(direction)


def _tangency(x: Vec, origin: Vec, rot: Vec, rays: list[_Rays]) -> Vec:
    """Per edge: distance of its viewing ray from the axis minus the radius [px].

    Edges against the pads get their own offset x[6]: their sub-pixel position is biased
    differently from edges against the backlight (a quarter of the contrast, limb shading).
    """
    point, direction = _axis(x, origin, rot)
    radius = 1e-3 * np.array([x[4], x[5]])
    out = []
    for r in rays:
        n = np.cross(r.direction, direction)
        dist = np.abs((point - r.centre) @ n.T) / np.linalg.norm(n, axis=1)
        out.append(r.weight * (dist - radius[r.part] - 1e-3 * x[6] * r.dark))
    return np.concatenate(out)


def _fit_axis(x0: Vec, origin: Vec, rot: Vec, rays: list[_Rays], prior: Vec) -> Vec:
    def residual(x: Vec) -> Vec:
        return np.r_[_tangency(x, origin, rot, rays), (x[4:7] - prior) / _PRIOR_MM]

    return least_squares(residual, x0, loss="soft_l1", f_scale=0.3, x_scale=_X_SCALE).x


def _tip_silhouette(cam: CameraModel, tip: Vec, direction: Vec, r_j: float, chamfer: float,
                    columns: Vec) -> Vec:
    """Row where the chamfered journal end's silhouette ends, at each column (convex frustum)."""
    a = np.cross(direction, [1.0, 0.0, 0.0] if abs(direction[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    ang = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    ring = np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * np.cross(direction, a)
    uv = cam.project(np.r_[tip + (r_j - chamfer) * ring, tip - chamfer * direction + r_j * ring])
    p = uv[cv2.convexHull(uv.astype(np.float32), returnPoints=False).ravel()]
    q = np.roll(p, -1, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (columns[:, None] - p[None, :, 0]) / (q[None, :, 0] - p[None, :, 0])
        v = p[None, :, 1] + s * (q[None, :, 1] - p[None, :, 1])
    v = np.where((s >= 0) & (s <= 1), v, np.nan)
    return np.nanmax(v, axis=1)


def inspect_in_hand(pair: StereoPair, left: NDArray[np.uint8], right: NDArray[np.uint8],
                    tcp_pos: Vec, tcp_rot: Vec, conductor: ConductorConfig = NOMINAL_CONDUCTOR,
                    config: InHandConfig = DEFAULT_CONFIG) -> InHandMeasurement:
    """Measure the held conductor's journal relative to the TCP from the two inspect images.

    `pair`: the calibrated inspect cameras at the images' size. `tcp_pos`, `tcp_rot`: the TCP
    pose in the base frame from the measured joint angles through the arm model. Raises
    ImageError for images that do not fit the cameras, ConductorNotInView when no conductor
    is between the fingers.
    """
    tcp_pos, tcp_rot = np.asarray(tcp_pos, float), np.asarray(tcp_rot, float)
    cams = (pair.left, pair.right)
    for cam, image in zip(cams, (left, right)):
        cam.check_image(image)
    edges = tuple(find_edges(c, im, tcp_pos, tcp_rot, conductor, config)
                  for c, im in zip(cams, (left, right)))
    origin = tcp_pos + config.grasp_height * tcp_rot[:, 2]

    def rays(masks: list[NDArray[np.bool_]]) -> list[_Rays]:
        out = []
        for c, e, m in zip(cams, edges, masks):
            px_per_m = float(c.K[0, 0]) / float(np.linalg.norm(origin - c.pos))
            out.append(_Rays(c.pos, c.rays(e.uv[m]), e.part[m], e.dark[m],
                             np.full(int(m.sum()), px_per_m)))
        return out

    prior = np.array([1e3 * BODY_H6.nominal / 2, 1e3 * JOURNAL_H6.nominal / 2, 0.0])
    # Backlit edges first (no pads in front of them), then everything within a tightening gate.
    x = _fit_axis(np.r_[0.0, 0.0, 0.0, 0.0, prior], origin, tcp_rot,
                  rays([~e.dark for e in edges]), prior)
    everything = rays([np.ones(len(e.uv), bool) for e in edges])
    for gate in (6 * config.gate_px, 2 * config.gate_px, config.gate_px):
        resid = np.split(np.abs(_tangency(x, origin, tcp_rot, everything)), [len(edges[0].uv)])
        inliers = [r < gate for r in resid]
        used = rays(inliers)
        x = _fit_axis(x, origin, tcp_rot, used, prior)
    point, direction = _axis(x, origin, tcp_rot)
    r_j = 1e-3 * x[5]

    def tip_residual(t: Vec) -> Vec:
        tip = point + 1e-3 * t[0] * direction
        return np.concatenate([
            e.tip_uv[:, 1] - _tip_silhouette(c, tip, direction, r_j, conductor.tip_chamfer,
                                             e.tip_uv[:, 0])
            for c, e in zip(cams, edges)])

    t = least_squares(tip_residual, [1e3 * conductor.journal_length], loss="soft_l1", f_scale=0.5,
                      diff_step=1e-4).x[0]
    tip_base = point + 1e-3 * t * direction
    tip, axis = tcp_rot.T @ (tip_base - tcp_pos), tcp_rot.T @ direction
    return InHandMeasurement(
        tip=tip, axis=axis, offset=tip[:2].copy(), tip_z=float(tip[2]),
        tilt=float(np.arccos(np.clip(axis[2], -1.0, 1.0))),
        tilt_direction=float(np.arctan2(axis[1], axis[0])), tip_base=tip_base,
        axis_base=direction, body_diameter=2e-3 * x[4], journal_diameter=2e-3 * x[5],
        rms_px=float(np.sqrt(np.mean(_tangency(x, origin, tcp_rot, used) ** 2))), edges=edges,
        inliers=(inliers[0], inliers[1]), conductor=conductor)
