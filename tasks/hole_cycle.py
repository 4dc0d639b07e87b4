"""The arm's moves of one hole cycle (steps 3 and 4 and the way to step 6), as the cell knows
them: every target comes from vision and the arm's measured joints, never from the simulator.

The poses: parts are taken from the tray and presented to the in-hand cameras with the
fingers closing along the world x axis (across the inspect cameras' line of sight), TCP z
down; at the inspection point the TCP leans by INSPECT_ROLL about the viewing direction (the
slanted-edge trick of :mod:`serpar.checks.vision_inhand_scenes`). Free-space moves first rise to
CLEAR_Z, above everything on the plate and the tray, then travel level.
"""

from __future__ import annotations

import numpy as np

from serpar.controllers.cell_runtime import CellRuntime
from serpar.kinematics.rotations import so3_exp
from serpar.sim.arm import TCP_OFFSET
from serpar.sim.conductor import mass_properties
from serpar.sim.poses import GRASP_HEIGHT
from serpar.sim.scene import Scene
from serpar.sim.tolerances import JOURNAL_H6
from serpar.tasks.motions import move_tcp, tcp_pose
from serpar.vision.inhand import InHandMeasurement
from serpar.vision.tray_conductors import ConductorSighting

HAND_DOWN = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
"""TCP x along world y, fingers (TCP y) closing along world x, TCP z down."""
INSPECT_ROLL = np.radians(5.0)
CLEAR_Z = 0.345
"""Travel height of the TCP [m]: the part's tip clears the plate, seated parts and the tray."""
TRAVEL_SPEED = 0.8
"""Peak TCP speed of the episode's free-space travel [m/s] (under the Panda's 1.7 m/s; faster
moves let the held part slide further in the pads)."""
FINE_SPEED = 0.08
"""Approach to the part and lift out of the pocket [m/s]."""
ABOVE_PART = 0.012
"""Pre-grasp height of the TCP above its grasp position [m]."""
LIFT = 0.02
GRASP_SQUEEZE = 20.0
"""Squeeze per pad [N] (the Franka Hand's grasp force)."""
OPEN_MARGIN = 1.5e-3
"""Jaw opening beyond the body diameter before a grasp [m]."""
HOVER = 0.004
"""Shoulder height above the hole entry at the hover [m] (tip 2.5 mm above)."""


def inspect_rotation(roll: float = INSPECT_ROLL) -> np.ndarray:
    """HAND_DOWN leaned by `roll` about the world y axis (the inspect cameras' line of sight)."""
    return so3_exp(np.array([0.0, -roll, 0.0])) @ HAND_DOWN


def travel(rt: CellRuntime, goal: np.ndarray, rot: np.ndarray, clear_z: float = CLEAR_Z) -> None:
    """Rise to clear_z, travel level to above the goal, then go down to it."""
    pos, _ = tcp_pose(rt)
    if pos[2] < clear_z - 1e-4:
        move_tcp(rt, np.array([pos[0], pos[1], clear_z]), rot, speed=TRAVEL_SPEED, settle_s=0.0)
    move_tcp(rt, np.array([goal[0], goal[1], max(clear_z, goal[2])]), rot, speed=TRAVEL_SPEED, settle_s=0.0)
    move_tcp(rt, np.asarray(goal, float), rot, speed=TRAVEL_SPEED, settle_s=0.1)


def pick(rt: CellRuntime, sighting: ConductorSighting, body_diameter: float) -> float:
    """Take the sighted conductor out of its pocket; returns the jaw width after the squeeze
    (about the body diameter when the part is in the hand, near 0 when it was missed).

    `body_diameter` is the nominal one: the cell does not know the drawn diameter."""
    grasp_tcp = sighting.shoulder + GRASP_HEIGHT * sighting.axis
    rt.gripper.open_to(body_diameter + OPEN_MARGIN)
    travel(rt, grasp_tcp + ABOVE_PART * sighting.axis, HAND_DOWN)
    move_tcp(rt, grasp_tcp, HAND_DOWN, speed=FINE_SPEED)
    rt.gripper.grasp(GRASP_SQUEEZE)
    rt.run(0.25)
    width = rt.gripper.width(rt.scene.data)
    if width > 0.5 * body_diameter:  # a part in the hand: tell the controller its load
        rt.set_load(*nominal_load(rt.scene, body_diameter))
    move_tcp(rt, grasp_tcp + LIFT * sighting.axis, HAND_DOWN, speed=FINE_SPEED, settle_s=0.0)
    return width


def nominal_load(scene: Scene, body_diameter: float) -> tuple[float, np.ndarray]:
    """The held conductor as a load (mass, CoM in the flange frame) from its drawing and the
    nominal grasp: the pads' centre GRASP_HEIGHT above the shoulder, the part along the TCP z."""
    mass, com_above_shoulder = mass_properties(scene.config.conductor, JOURNAL_H6.nominal, body_diameter)
    return mass, np.array([0.0, 0.0, TCP_OFFSET + GRASP_HEIGHT - com_above_shoulder])


def inspection_tcp(scene: Scene, roll: float = INSPECT_ROLL) -> np.ndarray:
    """TCP position that puts a nominal grasp's shoulder at the inspect pair's target."""
    pair = next(p for p in scene.config.stereo_pairs if p.name == "inspect")
    return np.array(pair.target) - GRASP_HEIGHT * inspect_rotation(roll)[:, 2]


def seat_tcp(hole_entry: np.ndarray, hand_rot: np.ndarray, held: InHandMeasurement,
             journal_length: float) -> np.ndarray:
    """Where the TCP is, at `hand_rot`, when the held part's shoulder sits on `hole_entry`."""
    shoulder_in_tcp = held.tip - journal_length * held.axis
    return np.asarray(hole_entry, float) - hand_rot @ shoulder_in_tcp


def release(rt: CellRuntime, body_diameter: float) -> None:
    """Open the hand on the seated part and back off along the TCP z."""
    rt.gripper.open_to(body_diameter + OPEN_MARGIN)
    rt.run(0.15)
    rt.set_load(0.0)
    pos, rot = tcp_pose(rt)
    move_tcp(rt, pos - 0.015 * rot[:, 2], rot, speed=FINE_SPEED * 2, settle_s=0.0)
