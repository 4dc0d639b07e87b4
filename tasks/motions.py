"""Motion primitives of the task, each a few control periods of the cell runtime.

Positions are TCP targets in the arm base frame as the controller knows it (its nominal model
at the measured joints); nothing here reads the simulator's true state.
"""

from __future__ import annotations

import numpy as np

from serpar.controllers.arm_controller import ControlLaw
from serpar.controllers.arm_laws import CartesianTarget, orientation_error
from serpar.controllers.cell_runtime import CellRuntime
from serpar.controllers.trajectory import PoseMove

DEFAULT_MOVE_SPEED = 0.25
"""Default peak TCP speed of `move_tcp` [m/s] (the min-jerk peak is 1.875x the mean); the
episode travels at `serpar.tasks.hole_cycle.TRAVEL_SPEED`."""
TURN_SPEED = 1.0
"""Peak rotation speed of free-space moves [rad/s]."""
MIN_MOVE_S = 0.15


def move_duration(start: np.ndarray, goal: np.ndarray, start_rot: np.ndarray,
                  goal_rot: np.ndarray, speed: float, turn_speed: float = TURN_SPEED) -> float:
    """Min-jerk duration whose peak speeds stay within `speed` [m/s] and `turn_speed` [rad/s]."""
    dist = float(np.linalg.norm(np.asarray(goal) - start))
    angle = float(np.linalg.norm(orientation_error(start_rot, goal_rot)))
    return max(1.875 * dist / speed, 1.875 * angle / turn_speed, MIN_MOVE_S)


def move_tcp(rt: CellRuntime, goal: np.ndarray, goal_rot: np.ndarray,
             speed: float = DEFAULT_MOVE_SPEED, settle_s: float = 0.1) -> None:
    """Impedance-controlled min-jerk move from the measured TCP pose to (goal, goal_rot)."""
    start, start_rot = rt.arm.nominal.tcp_pose()
    start, start_rot = start.copy(), start_rot.copy()
    move = PoseMove(start, np.asarray(goal, float), start_rot, np.asarray(goal_rot, float),
                    move_duration(start, goal, start_rot, goal_rot, speed))
    n = round(move.duration / rt.dt)
    for k in range(n):
        rt.arm.track(move.at((k + 1) * rt.dt), ControlLaw.IMPEDANCE)
        rt.step()
    hold(rt, CartesianTarget(np.asarray(goal, float), np.asarray(goal_rot, float)), settle_s)


def hold(rt: CellRuntime, target: CartesianTarget, seconds: float) -> None:
    rt.arm.track(target, ControlLaw.IMPEDANCE)
    rt.run(seconds)


def tcp_pose(rt: CellRuntime) -> tuple[np.ndarray, np.ndarray]:
    """The measured TCP pose (nominal model at the measured joints)."""
    pos, rot = rt.arm.nominal.tcp_pose()
    return pos.copy(), rot.copy()
