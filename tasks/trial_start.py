"""Where an insertion trial starts: one trial's sampled errors turned into the cell's state.

A trial is step 6 of the hole cycle from the hover, as the episode's insertion starts (the
measured tip ``HOVER_TIP`` above the hole entry as the cell believes it). What the cell got
wrong before then is in the draw: how the part really sits in the grip, what the in-hand
vision measured instead, and where the hole really is against where the cell put it. As in the
episode, the cell aligns what it *believes* (the measured journal over the believed entry); the
physics sees the truth. The plate is fixed with the hole axis vertical, so the hand turns to
bring the measured journal axis vertical (the episode tilts the plate to the journal instead;
the relative geometry is the same, gravity's direction differs by the tilt, ~0.1 deg).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.kinematics.rotations import so3_exp
from serpar.sim.arm import HOME_Q
from serpar.sim.conductor import ConductorConfig
from serpar.sim.poses import GRASP_HEIGHT, solve_site_pose
from serpar.sim.trial_scene import TrialIds
from serpar.tasks.hole_cycle import HAND_DOWN, HOVER

Vec = NDArray[np.float64]
UP = np.array([0.0, 0.0, 1.0])
HOVER_TIP = HOVER - ConductorConfig().journal_length
"""The journal tip above the hole entry at the hover, where the episode's insertion starts [m]
(the shoulder HOVER above it)."""
FLIP = np.diag([1.0, -1.0, -1.0])
"""A conductor's frame in the TCP frame at the nominal grasp: x along the TCP x, z (shoulder to
body) against the TCP z."""


@dataclass(frozen=True)
class TrialDraw:
    """One trial's sampled inputs [m, rad]; lateral vectors are (x, y) in the named frame."""

    hole_diameter: float
    journal_diameter: float
    body_diameter: float
    grasp_offset: float
    """The part's axis off the pads' centre along the pads (TCP x) [m] (true). Across them
    (TCP y) the coupled fingers centre it."""
    grasp_tilt: float
    """The journal axis's lean in the pads' plane, about the TCP y [rad] (true). Two flat pads
    squeezing a cylinder hold its axis parallel to their faces: no lean across them."""
    vision_tip: tuple[float, float]
    """In-hand vision's error of the tip centre, TCP frame (measured - true)."""
    vision_tilt: tuple[float, float]
    """In-hand vision's error of the axis, rotation vector about the TCP x and y."""
    hole_error: tuple[float, float]
    """The hole entry's true position minus where the cell believes it, world frame."""

    def __post_init__(self) -> None:
        values = [self.hole_diameter, self.journal_diameter, self.body_diameter,
                  self.grasp_offset, self.grasp_tilt, *self.vision_tip, *self.vision_tilt,
                  *self.hole_error]
        if not all(np.isfinite(values)):
            raise ConfigError(f"trial draw holds a non-finite value: {self}")
        if self.hole_diameter < self.journal_diameter:
            raise ConfigError(f"hole {self.hole_diameter * 1e3:.4f} mm < journal "
                              f"{self.journal_diameter * 1e3:.4f} mm: H7/h6 is a clearance fit")


@dataclass(frozen=True, eq=False)
class TrialStart:
    """The state a trial starts in and what its controller aims at, in the arm's base frame
    (the world's, unless the scene is ``at_origin``)."""

    q: Vec
    """Arm joint angles: the TCP at ``start`` with rotation ``rot``."""
    rot: Vec
    start: Vec
    """TCP position with the measured tip ``height`` above the believed entry."""
    seat: Vec
    """TCP position with the measured shoulder on the believed entry (insertion's seat_tcp)."""
    axis: Vec
    """Insertion direction: the measured journal axis, body to tip (down)."""
    part_pos: Vec
    part_quat: Vec
    """The conductor's true pose (shoulder; MuJoCo quaternion)."""
    finger: float
    """Each finger's opening: the pads just touching the part's body [m]."""
    height: float
    """The measured tip above the believed entry at ``start`` [m]."""


def _tilted(tilt: tuple[float, float]) -> Vec:
    return so3_exp(np.array([tilt[0], tilt[1], 0.0]))


def _aligning(a: Vec, b: Vec) -> Vec:
    """The smallest rotation taking unit vector a onto unit vector b."""
    axis = np.cross(a, b)
    s = float(np.linalg.norm(axis))
    if s < 1e-15:
        return np.eye(3)
    return so3_exp(axis / s * np.arctan2(s, float(a @ b)))


def trial_start(draw: TrialDraw, entry: Vec, journal_length: float, height: float = HOVER_TIP,
                ) -> tuple[Vec, Vec, Vec, Vec, Vec, Vec]:
    """(rot, start, seat, axis, part_pos, part_rot) of a trial, before the arm's joint angles."""
    grip = so3_exp(np.array([0.0, draw.grasp_tilt, 0.0]))  # the part's lean in the TCP frame
    shoulder = np.array([draw.grasp_offset, 0.0, GRASP_HEIGHT])
    axis_true = grip @ UP  # TCP frame, body -> tip
    tip_true = shoulder + journal_length * axis_true
    axis_seen = _tilted(draw.vision_tilt) @ axis_true
    tip_seen = tip_true + np.array([*draw.vision_tip, 0.0])
    # Turn the hand so that the measured axis points straight down.
    rot = _aligning(HAND_DOWN @ axis_seen, -UP) @ HAND_DOWN
    believed_entry = np.asarray(entry, float) - np.array([*draw.hole_error, 0.0])
    seat = believed_entry - rot @ (tip_seen - journal_length * axis_seen)
    start = seat + (journal_length + height) * UP
    part_rot = rot @ grip @ FLIP
    return rot, start, seat, rot @ axis_seen, start + rot @ shoulder, part_rot


def plan_start(model: mujoco.MjModel, ids: TrialIds, draw: TrialDraw, entry: Vec,
               journal_length: float, q_guess: Vec, height: float = HOVER_TIP) -> TrialStart:
    """A trial's start: the arm's joint angles (inverse kinematics seeded by ``q_guess``, its
    elbow where the controllers' posture task, pulling toward HOME_Q, leaves it) and where the
    part sits."""
    rot, start, seat, axis, part_pos, part_rot = trial_start(draw, entry, journal_length, height)
    q = solve_site_pose(model, model.qpos0, ids.arm_qpos, ids.tcp_site, start + ids.base, rotation=rot,
                        q_start=q_guess, rest=np.asarray(HOME_Q))
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(part_rot).ravel())
    return TrialStart(q, rot, start, seat, axis, part_pos, quat, draw.body_diameter / 2, height)


def write_start(qpos: Vec, ids: TrialIds, start: TrialStart) -> None:
    """Write the start's joint positions into one state's ``qpos`` (the rest is the model's)."""
    qpos[ids.arm_qpos] = start.q
    qpos[ids.finger_qpos] = start.finger
    qpos[ids.part_qpos:ids.part_qpos + 3] = start.part_pos + ids.base
    qpos[ids.part_qpos + 3:ids.part_qpos + 7] = start.part_quat


def place(model: mujoco.MjModel, data: mujoco.MjData, ids: TrialIds, start: TrialStart) -> None:
    """Put ``data`` into the trial's start, at rest: the arm, the fingers on the body, the part
    in the grip."""
    mujoco.mj_resetData(model, data)
    write_start(data.qpos, ids, start)
    mujoco.mj_forward(model, data)
