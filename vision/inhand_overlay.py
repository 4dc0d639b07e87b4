"""Pictures of an in-hand inspection: the edges found, the fitted silhouettes, axis and tip."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from serpar.vision.camera import CameraModel
from serpar.vision.inhand import InHandMeasurement

EDGE_RGB = (0, 200, 0)
REJECTED_RGB = (255, 150, 0)
SILHOUETTE_RGB = (0, 120, 255)
AXIS_RGB = (255, 0, 0)
TIP_RGB = (255, 0, 255)
_SHIFT = 4  # cv2 fixed-point bits: sub-pixel drawing


def _pts(uv: NDArray[np.float64]) -> NDArray[np.int32]:
    return np.round(uv * (1 << _SHIFT)).astype(np.int32).reshape(-1, 1, 2)


def _limbs(camera: CameraModel, start: NDArray[np.float64], axis: NDArray[np.float64],
           length: float, radius: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Image polylines of a cylinder's two silhouette edges (extremes of projected rings)."""
    a = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    ang = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    ring = radius * (np.cos(ang)[:, None] * a + np.sin(ang)[:, None] * np.cross(axis, a))
    ends = camera.project(np.array([start, start + length * axis]))
    d = (ends[1] - ends[0]) / max(float(np.linalg.norm(ends[1] - ends[0])), 1e-9)
    normal = np.array([-d[1], d[0]])
    lo, hi = [], []
    for s in np.linspace(0.0, length, 12):
        uv = camera.project(start + s * axis + ring)
        side = uv @ normal
        lo.append(uv[np.argmin(side)])
        hi.append(uv[np.argmax(side)])
    return np.array(lo), np.array(hi)


def draw_in_hand(image: NDArray[np.uint8], measurement: InHandMeasurement,
                 camera: CameraModel) -> NDArray[np.uint8]:
    """A copy of `image` (from `camera`) with the inspection drawn on it.

    Green dots: edge points used; orange: edge points the fit rejected (pads in front of the
    body); blue: the fitted body and journal silhouettes; red: the axis; magenta: the tip.
    """
    out = camera.check_image(image).copy()
    if out.ndim == 2:
        out = cv2.cvtColor(out, cv2.COLOR_GRAY2RGB)
    m, cfg = measurement, measurement.conductor
    axis = m.axis_base
    shoulder = m.tip_base - cfg.journal_length * axis
    for edges, inliers in zip(m.edges, m.inliers):
        if edges.camera == camera.name:
            colours = [EDGE_RGB if ok else REJECTED_RGB for ok in inliers]
            colours += [EDGE_RGB] * len(edges.tip_uv)
            for (u, v), colour in zip(np.r_[edges.uv, edges.tip_uv], colours):
                cv2.circle(out, (round(u * 16), round(v * 16)), 16, colour, -1, cv2.LINE_AA, _SHIFT)
    cylinders = ((shoulder, -axis, cfg.body_length, m.body_diameter / 2),
                 (m.tip_base, -axis, cfg.journal_length, m.journal_diameter / 2))
    for start, direction, length, radius in cylinders:
        for line in _limbs(camera, start, direction, length, radius):
            cv2.polylines(out, [_pts(line)], False, SILHOUETTE_RGB, 1, cv2.LINE_AA, _SHIFT)
    ends = camera.project(np.array([m.tip_base + 0.5e-3 * axis, shoulder - cfg.body_length * axis]))
    cv2.polylines(out, [_pts(ends)], False, AXIS_RGB, 1, cv2.LINE_AA, _SHIFT)
    tip = camera.project(m.tip_base[None])[0]
    size = max(3.0, 0.004 * camera.size[0])
    cv2.drawMarker(out, (round(tip[0]), round(tip[1])), TIP_RGB, cv2.MARKER_CROSS, int(2 * size), 1,
                   cv2.LINE_AA)
    return out
