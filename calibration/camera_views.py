"""The camera-calibration campaign: the arm carries a checkerboard through a spread of poses
in front of one stereo pair; at each pose both cameras take a frame and the arm reports its
measured joint angles.

The arm is placed at each pose kinematically and held still (mj_forward, no stepping): a
calibration run waits for the arm to settle before each shot, and what matters to the
method is only the resting pose, the frames and the encoder reading.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from serpar.controllers.arm_model import NominalArm
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import HOME_Q, Q_MAX, Q_MIN
from serpar.sim.arm_drive import quantise
from serpar.sim.calibration_board import BOARD_BODY, CheckerboardConfig
from serpar.sim.cameras import StereoPairConfig
from serpar.sim.poses import solve_tcp_pose
from serpar.sim.scene import Scene
from serpar.vision.imaging import Camera

ENCODER_COUNTS = 2**20


@dataclass(frozen=True)
class BoardView:
    """One calibration shot: measured TCP pose (from the encoders) and both frames."""

    q_measured: NDArray[np.float64]
    tcp_rot: NDArray[np.float64]
    tcp_pos: NDArray[np.float64]
    left: np.ndarray
    right: np.ndarray


def _board_base_rotation(pair: StereoPairConfig) -> NDArray[np.float64]:
    """TCP rotation that turns the board face (TCP x) towards the pair, long side along its baseline."""
    view = np.subtract(pair.target, pair.centre)
    if abs(view[2]) > 0.7 * np.linalg.norm(view):  # looking down: face up, TCP z sideways (-y)
        return np.column_stack([[0, 0, 1.0], [-1.0, 0, 0], [0, -1.0, 0]])
    face = -view / np.linalg.norm(view)  # looking sideways: face the cameras, TCP z down
    z = np.array([0, 0, -1.0]) - face[2] * -face
    z /= np.linalg.norm(z)
    return np.column_stack([face, np.cross(z, face), z])


@dataclass(frozen=True)
class CalibrationVolume:
    """Where the board goes: uniform in a box around `centre`, tilted up to `tilt_deg` each way."""

    centre: tuple[float, float, float]
    spread: tuple[float, float, float]
    """Half-widths of the box [m]."""
    tilt_deg: float
    views: int

    def __post_init__(self) -> None:
        if self.views < 3 or not 0 <= self.tilt_deg <= 45 or min(self.spread) < 0:
            raise ConfigError("calibration volume: views >= 3, tilt 0..45 deg, spreads >= 0")


TOP_VOLUME = CalibrationVolume(centre=(0.60, 0.135, 0.35), spread=(0.06, 0.15, 0.04), tilt_deg=20, views=50)
"""Across the top cameras' field above the baseplate (top face z ~ 0.30 m) and the tray
(conductor tops z ~ 0.235 m); the wrist beside the board keeps it from going lower, and
poses that would hit the cell are skipped."""
INSPECT_VOLUME = CalibrationVolume(centre=(0.45, -0.25, 0.35), spread=(0.008, 0.012, 0.006), tilt_deg=20,
                                   views=16)
"""Around the in-hand inspection point."""
VOLUMES = {"top": TOP_VOLUME, "inspect": INSPECT_VOLUME}


def board_poses(pair: StereoPairConfig, volume: CalibrationVolume,
                seed: int) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """(board centre, TCP rotation) targets spread through `volume`, board facing the pair."""
    rng = np.random.default_rng(seed)
    base = _board_base_rotation(pair)
    tilt_rad = np.radians(volume.tilt_deg)
    poses = []
    for _ in range(volume.views):
        centre = np.asarray(volume.centre) + rng.uniform(-1, 1, 3) * np.asarray(volume.spread)
        tilt = Rotation.from_rotvec(rng.uniform(-1, 1, 3) * tilt_rad @ base.T)
        poses.append((centre, tilt.as_matrix() @ base))
    return poses


def take_views(scene: Scene, pair: StereoPairConfig, board: CheckerboardConfig, camera: Camera,
               volume: CalibrationVolume, seed: int) -> list[BoardView]:
    """Put the board through the volume's poses (skipping unreachable ones); shoot the pair at each."""
    if scene.config.calibration_board != board:
        raise ConfigError("take_views: the scene must be built with this calibration_board")
    arm = NominalArm()
    _, pos_tb = board.tcp_to_board()
    views, q_prev = [], np.array(HOME_Q)
    rng = np.random.default_rng(seed)
    left_name, right_name = pair.camera_names()
    for centre, rot in board_poses(pair, volume, seed):
        tcp_target = centre - rot @ pos_tb
        q = _reach(scene, tcp_target, rot, q_prev, rng)
        if q is None:
            continue
        scene.reset()
        scene.data.qpos[scene.arm_qpos_adr] = q
        mujoco.mj_forward(scene.model, scene.data)
        if _collides(scene):
            continue
        q_prev = q
        q_meas = quantise(q, ENCODER_COUNTS)
        arm.load(q_meas, np.zeros(7))
        tcp_pos, tcp_rot = arm.tcp_pose()
        frames = camera.shoot(scene.data, (left_name, right_name))
        views.append(BoardView(q_meas, tcp_rot, tcp_pos, frames[left_name], frames[right_name]))
    return views


def _collides(scene: Scene) -> bool:
    """Whether the arm (beyond its base) or the board touches anything at this pose."""
    m, d = scene.model, scene.data
    base = m.body(names.ARM + "link0").id
    board = m.body(BOARD_BODY).id
    moving = {b for b in range(m.nbody) if b == board or (m.body(b).name.startswith(names.ARM) and b != base)}
    for c in d.contact[: d.ncon]:
        b1, b2 = m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]
        if (b1 in moving) != (b2 in moving) and c.dist < c.includemargin:  # margin: a shrunk geom
            return True
    return False


def _reach(scene: Scene, tcp: NDArray[np.float64], rot: NDArray[np.float64], q_prev: NDArray[np.float64],
           rng: np.random.Generator, restarts: int = 12) -> NDArray[np.float64] | None:
    """Joint angles for the TCP frame: from the previous pose first, then from random starts."""
    starts = [q_prev] + [rng.uniform(Q_MIN, Q_MAX) for _ in range(restarts)]
    for q0 in starts:
        try:
            return solve_tcp_pose(scene, tcp, rotation=rot, q_start=q0)
        except ConfigError:
            continue
    return None
