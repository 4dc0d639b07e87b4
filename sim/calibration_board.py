"""Checkerboard calibration targets carried by the arm (one per stereo pair).

The pattern is built from flush tiles (black and white boxes of one thickness
tiling the face) rather than raised squares or a texture: the corners are exact
and no square edge casts a sliver of side face into an oblique view.

Board frame: origin at the centre of the patterned face, z out of the face, x
along the long side (``squares[0]``), y along the short side. The first square
(at -x, -y) is black; with an even x odd square count the pattern is not 180 deg
symmetric, so a detector can tell which corner is first.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim import names

BLACK = (0.04, 0.04, 0.04, 1.0)
WHITE = (0.82, 0.82, 0.82, 1.0)
"""Matte print on an aluminium composite panel; white below saturation under the cell lights."""
BOARD_BODY = "calibration_board"


@dataclass(frozen=True)
class CheckerboardConfig:
    """Pattern and mount of one board [m]."""

    squares: tuple[int, int] = (10, 7)
    """Squares along the board's x and y; the inner corners are one fewer each way."""
    square: float = 0.010
    border: float = 0.010
    """White quiet zone around the pattern (the detector needs it)."""
    thickness: float = 0.002
    mount_offset: float = 0.034
    """The face stands this far from the TCP axis along the TCP x axis (clear of the hand body)."""
    mount_height: float = -0.012
    """Board centre along the TCP z from the TCP (negative: towards the flange)."""

    def __post_init__(self) -> None:
        nx, ny = self.squares
        if nx < 3 or ny < 3 or (nx + ny) % 2 == 0:
            raise ConfigError(f"board squares {self.squares}: need >= 3 each way and one even, one odd "
                              "count (so the pattern's orientation is unambiguous)")
        if not 1e-3 <= self.square <= 0.05:
            raise ConfigError(f"board square {self.square:g} m ({self.square * 1e3:g} mm): valid 0.001..0.05 m "
                              "(1..50 mm); lengths in a config are in metres")

    @property
    def inner_corners(self) -> tuple[int, int]:
        return self.squares[0] - 1, self.squares[1] - 1

    def corner_points(self) -> np.ndarray:
        """(N, 3) inner corners in the board frame, row by row along x (OpenCV's order)."""
        cx, cy = self.inner_corners
        i, j = np.meshgrid(np.arange(cx), np.arange(cy))
        x = (i.ravel() - (cx - 1) / 2) * self.square
        y = (j.ravel() - (cy - 1) / 2) * self.square
        return np.c_[x, y, np.zeros_like(x)]

    def tcp_to_board(self) -> tuple[np.ndarray, np.ndarray]:
        """Nominal board pose in the TCP frame (rotation, position): board z = TCP x."""
        rot = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # columns: TCP y, z, x
        return rot, np.array([self.mount_offset, 0.0, self.mount_height])


TOP_BOARD = CheckerboardConfig()
"""100 x 70 mm pattern, 10 mm squares: ~52 px per square in the top cameras at full size."""
INSPECT_BOARD = CheckerboardConfig(square=0.0025, border=0.003, mount_offset=0.034, mount_height=0.0)
"""25 x 17.5 mm pattern, 2.5 mm squares: fits the in-hand cameras' 57 x 43 mm field of view."""
BOARDS = {"top": TOP_BOARD, "inspect": INSPECT_BOARD}


def _matte(spec: mujoco.MjSpec, name: str, rgba: tuple[float, ...]) -> str:
    mat = spec.add_material(name=name)
    mat.rgba, mat.specular, mat.shininess, mat.reflectance = list(rgba), 0.0, 0.0, 0.0
    return name


def add_board(spec: mujoco.MjSpec, board: CheckerboardConfig) -> None:
    """Mount `board` on the arm's hand at its nominal pose (call after the arm is attached)."""
    hand = spec.body(names.ARM + "hand")
    tcp = spec.site(names.ARM + "tcp")
    if hand is None or tcp is None:
        raise ConfigError("add_board: the spec has no arm hand/tcp; attach the arm first")
    rot, pos = board.tcp_to_board()
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.ravel())
    body = hand.add_body(name=BOARD_BODY, pos=(np.array(tcp.pos) + pos).tolist(), quat=quat.tolist())
    black, white = _matte(spec, "board_black", BLACK), _matte(spec, "board_white", WHITE)
    nx, ny = board.squares
    s, t, b = board.square, board.thickness / 2, board.border

    def tile(cx: float, cy: float, hx: float, hy: float, material: str) -> None:
        # Collidable so a calibration campaign can reject poses that would hit the cell.
        g = body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[hx, hy, t], pos=[cx, cy, -t],
                          material=material)
        g.density = 300.0  # light composite panel

    for i in range(nx):
        for j in range(ny):
            tile((i - (nx - 1) / 2) * s, (j - (ny - 1) / 2) * s, s / 2, s / 2,
                 black if (i + j) % 2 == 0 else white)
    half_x, half_y = nx * s / 2, ny * s / 2
    for sign in (-1, 1):  # white border: two long strips, two short ones between them
        tile(0.0, sign * (half_y + b / 2), half_x + b, b / 2, white)
        tile(sign * (half_x + b / 2), 0.0, b / 2, half_y, white)
