"""A platform built with hidden joint errors (seed 000 Table 5) moves where its *built*
kinematics say, not where its nominal model was commanded to."""

import mujoco
import numpy as np
import pytest

from serpar.controllers.stewart_servo import StewartServo, platform_pose
from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import forward_kinematics
from serpar.kinematics.stewart_table import table5_errors
from serpar.sim import names
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.stewart import StewartConfig, built_geometry, initial_pose, loop_violation


@pytest.fixture(scope="module")
def built_cell():
    cfg = SceneConfig(n_conductors=0,
                      stewart=StewartConfig(joint_errors=tuple(map(tuple, table5_errors()))))
    return cfg, build_scene(cfg)


def test_loops_closed_at_the_pose_the_errors_give(built_cell):
    cfg, scene = built_cell
    m, d = scene.model, scene.data
    assert loop_violation(m, d, names.STEWART) < 1e-9
    pos, rot = platform_pose(m, d, names.STEWART)
    pos0, rot0 = initial_pose(cfg.stewart)
    assert np.max(np.abs(pos - pos0)) < 1e-9 and np.max(np.abs(rot - rot0)) < 1e-9
    # Table 5 puts the platform millimetres away from where its model thinks it is.
    assert 1e-3 < np.linalg.norm(pos - cfg.stewart.home_pos) < 5e-3


def test_commanded_move_lands_where_the_built_kinematics_say(built_cell):
    cfg, scene = built_cell
    m, d = scene.model, scene.data
    servo = StewartServo.from_model(m, cfg.stewart.geometry(), names.STEWART, match_tol=0.01)
    target = np.array(cfg.stewart.home_pos) + [0.0, 0.025, 0.0]
    strokes = servo.command_pose(d, target, np.eye(3))
    mujoco.mj_step(m, d, nstep=20000)
    pos, _ = platform_pose(m, d, names.STEWART)
    built, dl = built_geometry(cfg.stewart)
    predicted, _, _ = forward_kinematics(built, strokes + dl, target, np.eye(3))
    assert np.max(np.abs(pos - predicted)) < 1e-6
    assert np.linalg.norm(pos - target) > 1e-3  # the nominal model is wrong by mm


def test_servo_refuses_another_robot_by_default(built_cell):
    cfg, scene = built_cell
    with pytest.raises(ConfigError, match="differ from the geometry"):
        StewartServo.from_model(scene.model, cfg.stewart.geometry(), names.STEWART)


@pytest.mark.parametrize("errors, message", [
    (((0.0,) * 7,) * 5, "6 rows of 7"),
    (((0.02,) + (0.0,) * 6,) * 6, "valid: \\|error\\| <= 10 mm"),
])
def test_bad_joint_errors(errors, message):
    with pytest.raises(ConfigError, match=message):
        StewartConfig(joint_errors=errors)
