"""Step-4 edge finding: sub-pixel silhouette edges of the held conductor in one in-hand image
(body against the backlight and the pads, journal against the backlight, the tip's lower
end). :mod:`serpar.vision.inhand` fits the axis to what this finds, over both cameras."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from serpar.sim.conductor import ConductorConfig
from serpar.sim.tolerances import BODY_H6, JOURNAL_H6
from serpar.vision.camera import CameraModel
from serpar.vision.errors import ConductorNotInView, VisionError

Vec = NDArray[np.float64]
BODY, JOURNAL = 0, 1
NOMINAL_CONDUCTOR = ConductorConfig()


@dataclass(frozen=True)
class InHandConfig:
    """Detector settings; lengths in metres so that they hold at any readout size."""

    grasp_height: float = 0.006
    """Nominal shoulder distance below the TCP along its z (places the search window only)."""
    search_margin: float = 0.0015
    """Room around the nominal part for grasp errors [m]."""
    chroma_threshold: int = 15
    """Brass pixels: red minus blue above this (backlight, pads and fingers are grey)."""
    min_area_fraction: float = 0.3
    """Below this fraction of the expected brass area the part counts as not in view."""
    end_margin: float = 1e-4
    """Rows this close to where a silhouette edge ends are not used [m]."""
    gate_px: float = 0.5
    """Final outlier gate on the tangency residual [px] (rejects pad edges in front of the body)."""

    def __post_init__(self) -> None:
        if not (0 < self.chroma_threshold < 128 and 0 < self.min_area_fraction <= 1
                and self.gate_px > 0):
            raise VisionError("in-hand config: chroma_threshold in 1..127, min_area_fraction in "
                              "(0, 1], gate_px > 0")


@dataclass(frozen=True, eq=False)
class CameraEdges:
    """Silhouette edge points found in one image [px]."""

    camera: str
    uv: Vec
    """(N, 2) side edges: sub-pixel u at row v."""
    part: NDArray[np.int64]
    """(N,) BODY or JOURNAL."""
    dark: NDArray[np.bool_]
    """(N,) True where the background is a pad, False for the backlight."""
    tip_uv: Vec
    """(M, 2) lower end of the journal silhouette: sub-pixel v at column u."""


def _subpixel(profile: Vec, i0: int, step: int) -> float:
    """Edge in `profile` whose first inside pixel is `i0`, the outside lying towards `step`.

    Area method: covered fractions of the pixels at the edge, between the outside level and
    the inside level extrapolated to the edge.
    """
    outside = 0.5 * (profile[i0 + 4 * step] + profile[i0 + 5 * step])
    span = 2.0 * profile[i0 - step] - profile[i0 - 2 * step] - outside
    if abs(span) < 8.0:
        return np.nan
    cover = np.clip((profile[[i0 + 2 * step, i0 + step, i0]] - outside) / span, 0.0, 1.0).sum()
    return i0 - 0.5 * step + step * float(cover)


def _window(cam: CameraModel, shoulder: Vec, rot: Vec, cfg: ConductorConfig,
            ext: float) -> tuple[int, ...]:
    """Pixel box (u0, v0, u1, v1) around the nominal part, widened by `ext` [m]."""
    z, e1, e2 = rot[:, 2], rot[:, 0], rot[:, 1]
    corners = [shoulder + t * z + a * e1 + b * e2
               for t in (-cfg.body_length - ext, cfg.journal_length + ext)
               for a in (-ext, ext) for b in (-ext, ext)]
    uv = cam.project(np.array(corners))
    lo, hi = np.floor(uv.min(axis=0)).astype(int) - 8, np.ceil(uv.max(axis=0)).astype(int) + 8
    return max(lo[0], 0), max(lo[1], 0), min(hi[0], cam.size[0]), min(hi[1], cam.size[1])


def find_edges(cam: CameraModel, image: NDArray[np.uint8], tcp_pos: Vec, tcp_rot: Vec,
               conductor: ConductorConfig = NOMINAL_CONDUCTOR,
               config: InHandConfig = InHandConfig()) -> CameraEdges:
    """Silhouette edges of the held conductor in one image; ConductorNotInView if there is none."""
    img = cam.check_image(image)
    if img.ndim != 3:
        raise VisionError(f"camera {cam.name}: in-hand inspection needs colour images "
                          "(brass against grey)")
    z = tcp_rot[:, 2]
    shoulder = tcp_pos + config.grasp_height * z
    scale = float(cam.K[0, 0]) / float(cam.to_camera(shoulder)[0, 2])  # px per m at the part
    ends = cam.project(np.array([shoulder - conductor.body_length * z, shoulder]))
    down = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    if down[1] < 0.85:  # rows cross the silhouette edges; the tip is the lowest brass
        raise VisionError(f"camera {cam.name}: the journal must point down the image (it points "
                          f"{np.round(down, 2)})")
    r_b, r_j = BODY_H6.nominal / 2, JOURNAL_H6.nominal / 2
    u0, v0, u1, v1 = _window(cam, shoulder, tcp_rot, conductor, r_b + config.search_margin)
    if u1 - u0 < 16 or v1 - v0 < 16:
        raise ConductorNotInView(f"camera {cam.name}: the gripper is outside the image")
    roi = img[v0:v1, u0:u1].astype(float)
    red, blue, grey = roi[..., 0], roi[..., 2], roi.mean(axis=2)
    mask = (red - blue > config.chroma_threshold) & (grey < 200)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    expected = 2 * (r_b * conductor.body_length + r_j * conductor.journal_length) * scale**2
    if n < 2 or stats[1:, cv2.CC_STAT_AREA].max() < config.min_area_fraction * expected:
        raise ConductorNotInView(f"camera {cam.name}: no conductor between the fingers "
                                 f"(expected ~{expected:.0f} brass pixels)")
    blob = labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    rows = np.flatnonzero(blob.any(axis=1))
    left = np.array([np.flatnonzero(blob[r])[0] for r in rows])
    right = np.array([np.flatnonzero(blob[r])[-1] for r in rows])
    width = right - left + 1
    is_journal = width < (r_b + r_j) * scale
    if is_journal.all() or not is_journal.any():
        raise ConductorNotInView(f"camera {cam.name}: brass found, but not a body with a journal")
    # Leave out rows where a silhouette edge ends: cap ellipses (half-height r sin(elevation),
    # with room for the grasp tilt), the tip chamfer, plus a margin.
    sin_e = abs(float(cam.rays(cam.project(shoulder[None]))[0] @ z)) + 0.06
    cap = (r_b * sin_e + config.end_margin) * scale
    tip_cap = (r_j * sin_e + conductor.tip_chamfer + config.end_margin) * scale
    body_rows = rows[~is_journal]
    ok_body = ~is_journal & (rows > body_rows.min() + cap) & (rows < body_rows.max() - cap)
    # The journal's edges start past the last row wider than a journal (the shoulder face).
    wide = rows[width > np.median(width[is_journal]) + 2]
    tip_row = rows[is_journal].max()
    ok_journal = is_journal & (rows > wide.max() + 2) & (rows < tip_row - tip_cap)
    pts, parts, darks = [], [], []
    for k in np.flatnonzero(ok_body | ok_journal):
        r = rows[k]
        for i0, step in ((left[k], -1), (right[k], 1)):
            if not 0 <= i0 + 6 * step < blob.shape[1]:
                continue
            out = grey[r, i0 + 4 * step:i0 + 7 * step:step]
            if out.min() > 200:  # backlight: the blue channel has the most contrast against brass
                dark, profile = False, blue[r]
            elif out.max() < 120 and abs(red[r, i0 + 4 * step] - blue[r, i0 + 4 * step]) < 15:
                dark, profile = True, red[r]  # a grey pad: red has the contrast
            else:
                continue
            e = _subpixel(profile, int(i0), step)
            if np.isfinite(e):
                pts.append((u0 + e, v0 + r))
                parts.append(JOURNAL if is_journal[k] else BODY)
                darks.append(dark)
    tip = []
    if ok_journal.sum() >= 3:  # columns about the journal's centre line, extrapolated to its end
        line = np.polyfit(rows[ok_journal], 0.5 * (left + right)[ok_journal], 1)
        centre = np.polyval(line, tip_row)
        half = 0.5 * (r_j - conductor.tip_chamfer) * scale
        first = max(int(np.ceil(centre - half)), 0)
        for c in range(first, min(int(np.floor(centre + half)), blob.shape[1] - 1) + 1):
            col = np.flatnonzero(blob[:, c])
            j0 = int(col[-1]) if len(col) else blob.shape[0]
            if j0 + 6 < blob.shape[0] and grey[j0 + 4:j0 + 7, c].min() > 200:
                e = _subpixel(blue[:, c], j0, 1)
                if np.isfinite(e):
                    tip.append((u0 + c, v0 + e))
    if len(pts) < 20 or len(tip) < 3:
        raise ConductorNotInView(f"camera {cam.name}: too few silhouette edges of a conductor "
                                 f"({len(pts)} along its sides, {len(tip)} at the tip)")
    return CameraEdges(cam.name, np.array(pts, float), np.array(parts), np.array(darks),
                       np.array(tip, float))
