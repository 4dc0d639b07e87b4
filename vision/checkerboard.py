"""Finding the checkerboard's inner corners in a frame, in the board's own corner order."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from serpar.sim.calibration_board import CheckerboardConfig
from serpar.vision.errors import TargetNotFound


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def _first_square_is_black(grey: np.ndarray, corners: NDArray[np.float64], nx: int, ny: int) -> bool:
    """Whether the squares inside the corner grid are coloured as in the board's own order.

    Square (i+1, j+1) lies between corners (i, j) and (i+1, j+1) and is black when i + j is
    even; every such square is inside the detected grid, so all of them can be sampled.
    """
    grid = corners.reshape(ny, nx, 2)
    centres = 0.5 * (grid[:-1, :-1] + grid[1:, 1:])
    h, w = grey.shape
    u = np.clip(np.rint(centres[..., 0]).astype(int), 0, w - 1)
    v = np.clip(np.rint(centres[..., 1]).astype(int), 0, h - 1)
    levels = grey[v, u].astype(float)
    even = (np.add.outer(np.arange(ny - 1), np.arange(nx - 1)) % 2) == 0
    return float(levels[even].mean()) < float(levels[~even].mean())


def _require_whole_board(corners: NDArray[np.float64], nx: int, ny: int, shape: tuple[int, ...]) -> None:
    """The pattern's outer corners (one square beyond the inner grid) must be inside the frame:
    a board cut by the frame edge can yield a shifted sub-grid that looks complete."""
    grid = corners.reshape(ny, nx, 2)
    outer = []
    for j, dj in ((0, -1), (ny - 1, 1)):
        for i, di in ((0, -1), (nx - 1, 1)):
            step_x = grid[j, i] - grid[j, i - di]
            step_y = grid[j, i] - grid[j - dj, i]
            outer.append(grid[j, i] + step_x + step_y)
    outer_arr = np.array(outer)
    h, w = shape[:2]
    if np.any(outer_arr < 2) or np.any(outer_arr[:, 0] > w - 3) or np.any(outer_arr[:, 1] > h - 3):
        raise TargetNotFound("the checkerboard is cut by the frame edge")


def _detect(grey: np.ndarray, pattern: tuple[int, int]) -> NDArray[np.float64] | None:
    """OpenCV's sector-based detector: found coarsely at half size, then at full accuracy on a
    crop around the board (the accurate mode costs ~1 s on a whole 3.2 MP frame)."""
    small = cv2.resize(grey, None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA)
    found, coarse = cv2.findChessboardCornersSB(small, pattern, flags=0)
    if found and coarse is not None:
        c = coarse.reshape(-1, 2) * 2 + 0.5
        square = float(np.median(np.linalg.norm(np.diff(c, axis=0), axis=1)))
        lo = np.maximum(np.floor(c.min(axis=0) - 2 * square), 0).astype(int)
        hi = np.minimum(np.ceil(c.max(axis=0) + 2 * square), grey.shape[::-1]).astype(int)
        crop = np.ascontiguousarray(grey[lo[1]:hi[1], lo[0]:hi[0]])
        found, fine = cv2.findChessboardCornersSB(crop, pattern, flags=cv2.CALIB_CB_ACCURACY)
        if found and fine is not None:
            return fine.reshape(-1, 2).astype(np.float64) + lo
    found, full = cv2.findChessboardCornersSB(grey, pattern, flags=cv2.CALIB_CB_ACCURACY
                                              | cv2.CALIB_CB_EXHAUSTIVE)
    return full.reshape(-1, 2).astype(np.float64) if found and full is not None else None


def find_corners(image: np.ndarray, board: CheckerboardConfig) -> NDArray[np.float64]:
    """(N, 2) sub-pixel inner corners ordered like ``board.corner_points()``; TargetNotFound if absent.

    OpenCV's sector-based detector returns the corners row by row from any corner, in either
    handedness. The handedness is fixed by the board facing the camera (its z towards the
    lens), and the asymmetric colouring (square 0 black) then fixes which end is first.
    """
    grey = _grey(image)
    nx, ny = board.inner_corners
    pts = _detect(grey, (nx, ny))
    if pts is None or len(pts) != nx * ny:
        raise TargetNotFound(f"no complete {nx}x{ny}-corner checkerboard in the image")
    _require_whole_board(pts, nx, ny, grey.shape)
    a, b = pts[1] - pts[0], pts[nx] - pts[0]
    if a[0] * b[1] - a[1] * b[0] > 0:  # mirrored order (board x, y would make z point away): flip rows
        pts = pts.reshape(ny, nx, 2)[::-1].reshape(-1, 2).copy()
    if not _first_square_is_black(grey, pts, nx, ny):
        pts = pts[::-1].copy()
    return pts


def draw_corners(image: np.ndarray, corners: NDArray[np.float64], board: CheckerboardConfig) -> np.ndarray:
    """A copy of `image` with the detected corners drawn (corner 0 ringed)."""
    out = image.copy() if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    cv2.drawChessboardCorners(out, board.inner_corners, corners.astype(np.float32).reshape(-1, 1, 2), True)
    cv2.circle(out, tuple(int(np.rint(c)) for c in corners[0]), 12, (255, 0, 255), 2)
    return out
