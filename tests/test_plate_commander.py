"""The step-5 plate commander as the cell uses it: the model's plate pose, goal_for and the
follower that keeps a hole under a journal wandering sideways (all from the model alone)."""

import numpy as np
import pytest

from serpar.controllers.plate_commander import PlateCommander, transform
from serpar.sim.scene import SceneConfig, build_scene
from serpar.tasks.episode_steps import HoleUnderJournal

AXIS = np.array([0.0, 0.0, -1.0])  # journal direction, body -> tip
HOLE_IN_PLATE = np.array([0.02, -0.015, 0.0])
AXIS_IN_PLATE = np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def commander():
    scene = build_scene(SceneConfig(n_conductors=0))
    plate = PlateCommander.create(scene.model, scene.data, scene.config.stewart, None)
    plate.base_T_stewart = transform(np.eye(3), np.array(scene.config.stewart_base))
    return plate, scene.data


def _hole(plate: PlateCommander) -> np.ndarray:
    pose = plate.plate_pose()
    return pose[:3, :3] @ HOLE_IN_PLATE + pose[:3, 3]


def test_goal_puts_the_hole_entry_at_the_point(commander):
    plate, data = commander
    entry = np.array([0.601, 0.002, 0.299])
    plate.nudge(data, plate.goal_for(HOLE_IN_PLATE, AXIS_IN_PLATE, entry, -AXIS))
    assert np.linalg.norm(_hole(plate) - entry) < 1e-9


def test_follower_tracks_sideways_wander_only(commander):
    plate, data = commander
    start, entry = np.array([0.6, 0.0, 0.40]), np.array([0.6, 0.0, 0.299])
    plate.nudge(data, plate.goal_for(HOLE_IN_PLATE, AXIS_IN_PLATE, entry, -AXIS))
    follow = HoleUnderJournal(plate, data, HOLE_IN_PLATE, AXIS_IN_PLATE, entry, AXIS, start,
                              stop_after=0.003, every=1)
    follow(start + np.array([4e-5, -3e-5, -0.002]))  # 2 mm down, 50 um sideways
    assert np.allclose(_hole(plate), entry + np.array([4e-5, -3e-5, 0.0]), atol=1e-9)
    before = plate.commanded.copy()
    follow(start + np.array([4.1e-5, -3e-5, -0.0025]))  # 1 um more: inside the dead band
    assert np.array_equal(plate.commanded, before)


def test_follower_stops_before_the_tip_can_touch(commander):
    """Past `stop_after` along the axis the hole holds still, however far the TCP wanders: a
    hole chasing a tip that its chamfer pushes sideways would drive the chamfer into it."""
    plate, data = commander
    start, entry = np.array([0.6, 0.0, 0.40]), np.array([0.6, 0.0, 0.299])
    plate.nudge(data, plate.goal_for(HOLE_IN_PLATE, AXIS_IN_PLATE, entry, -AXIS))
    follow = HoleUnderJournal(plate, data, HOLE_IN_PLATE, AXIS_IN_PLATE, entry, AXIS, start,
                              stop_after=0.002, every=1)
    follow(start + np.array([2e-5, 0.0, -0.0019]))  # still above: followed
    assert np.allclose(_hole(plate), entry + np.array([2e-5, 0.0, 0.0]), atol=1e-9)
    before = plate.commanded.copy()
    follow(start + np.array([9e-5, 0.0, -0.0021]))  # past the stop: 70 um more, not followed
    assert np.array_equal(plate.commanded, before)
