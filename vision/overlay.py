"""Drawings of step-1 and step-2 detections on a copy of a camera frame (RGB, uint8).

Shared style: one colour per status, thin lines scaled to the frame width, labels next to
each mark. Positions are drawn where the measurement puts them (projected with the given
camera), so a drawing also shows how well the fit explains the pixels.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from serpar.sim.baseplate import BaseplateConfig
from serpar.vision.camera import CameraModel
from serpar.vision.plate import NOMINAL_PLATE, PlateMeasurement
from serpar.vision.tray_conductors import BODY_DIAMETER, ConductorSighting

STATUS_RGB: dict[str, tuple[int, int, int]] = {
    "empty": (40, 200, 60),
    "occupied": (255, 140, 0),
    "unseen": (230, 30, 30),
}
"""Status colours (RGB): empty holes green, occupied orange, unseen red."""
CONDUCTOR_RGB = (0, 170, 255)
PLATE_RGB = (160, 60, 220)


def _canvas(image: np.ndarray) -> tuple[NDArray[np.uint8], int, float]:
    """RGB copy of `image`, line thickness and font scale for its width."""
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB) if image.ndim == 2 else image.copy()
    s = out.shape[1] / 2048
    return out, max(1, round(2 * s)), 0.8 * max(s, 0.5)


def _pt(uv: np.ndarray) -> tuple[int, int]:
    return round(float(uv[0])), round(float(uv[1]))


def _radius_px(camera: CameraModel, centre: np.ndarray, radius: float) -> int:
    depth = float(camera.to_camera(centre)[0, 2])
    return max(2, round(radius * camera.K[0, 0] / depth))


def draw_plate(image: np.ndarray, measurement: PlateMeasurement, camera: CameraModel,
               plate: BaseplateConfig = NOMINAL_PLATE) -> NDArray[np.uint8]:
    """Holes (circle per hole in its status colour, index, dashes for unseen ones) and the
    fitted plate outline drawn on a copy of `image` as seen by `camera`."""
    out, thick, font = _canvas(image)
    rot, origin = measurement.rotation, measurement.origin
    hx = plate.cols * plate.pitch / 2 + plate.margin
    hy = plate.rows * plate.pitch / 2 + plate.margin
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    outline = np.c_[corners, np.full(4, plate.thickness)] @ rot.T + origin
    cv2.polylines(out, [np.round(camera.project(outline)).astype(np.int32)], True, PLATE_RGB, thick,
                  cv2.LINE_AA)
    for hole in measurement.holes:
        uv = camera.project(hole.centre)[0]
        colour = STATUS_RGB[hole.status]
        r = _radius_px(camera, hole.centre, 1.5e-3)
        if hole.status == "unseen":
            for a in range(0, 360, 45):
                cv2.ellipse(out, _pt(uv), (r, r), 0, a, a + 25, colour, thick, cv2.LINE_AA)
        else:
            cv2.circle(out, _pt(uv), r, colour, thick, cv2.LINE_AA)
        cv2.putText(out, str(hole.index), _pt(uv + (r + 2, -r - 2)), cv2.FONT_HERSHEY_SIMPLEX,
                    font, colour, thick, cv2.LINE_AA)
    return out


def draw_conductors(image: np.ndarray, sightings: Sequence[ConductorSighting],
                    camera: CameraModel) -> NDArray[np.uint8]:
    """Each conductor's measured top (circle of the body diameter), its axis down to the
    shoulder, and its pocket index (or '?'), drawn on a copy of `image`."""
    out, thick, font = _canvas(image)
    for s in sightings:
        top, shoulder = camera.project(np.array([s.top, s.shoulder]))
        r = _radius_px(camera, s.top, BODY_DIAMETER / 2)
        cv2.circle(out, _pt(top), r, CONDUCTOR_RGB, thick, cv2.LINE_AA)
        cv2.line(out, _pt(top), _pt(shoulder), CONDUCTOR_RGB, thick, cv2.LINE_AA)
        cv2.drawMarker(out, _pt(top), CONDUCTOR_RGB, cv2.MARKER_CROSS, r, thick)
        label = "?" if s.pocket is None else str(s.pocket)
        cv2.putText(out, label, _pt(top + (r + 2, -r - 2)), cv2.FONT_HERSHEY_SIMPLEX, font,
                    CONDUCTOR_RGB, thick, cv2.LINE_AA)
    return out
