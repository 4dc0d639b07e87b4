"""Island sleeping (PhysicsConfig.sleep): resting parts stop costing steps, but nothing that
should move stays frozen — a push or a kinematic placement wakes a sleeping conductor, and a
leg command wakes the sleeping platform with the parts seated in its plate."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.checks.vision_scenes import seat_conductor
from serpar.controllers.stewart_servo import StewartServo
from serpar.sim import names
from serpar.sim.physics import PhysicsConfig
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.stewart import built_geometry


@pytest.fixture()
def resting():
    """Two conductors left 0.8 s in the tray: asleep."""
    scene = build_scene(SceneConfig(n_conductors=2))
    for _ in range(8000):
        mujoco.mj_step(scene.model, scene.data)
    return scene


def _asleep(scene, k: int) -> bool:
    return bool(scene.data.tree_asleep[scene.model.body_treeid[scene.conductor_bodies[k]]] >= 0)


def test_resting_parts_sleep_and_the_arm_never_does(resting):
    m, d = resting.model, resting.data
    assert _asleep(resting, 0) and _asleep(resting, 1)
    arm_tree = m.body_treeid[m.body("arm/link1").id]
    assert d.tree_asleep[arm_tree] < 0
    assert mujoco.mjtSleepPolicy(m.tree_sleep_policy[arm_tree]).name.endswith("NEVER")


def test_a_push_wakes_a_sleeping_part(resting):
    m, d = resting.model, resting.data
    body = resting.conductor_bodies[0]
    z0 = d.xpos[body][2]
    d.xfrc_applied[body] = [0, 0, 0.05, 0, 0, 0]  # 3x its weight, upwards, for 10 ms
    for _ in range(100):
        mujoco.mj_step(m, d)
    assert not _asleep(resting, 0)
    assert d.xpos[body][2] - z0 > 1e-4
    assert _asleep(resting, 1)  # the other part, untouched, sleeps on


def test_a_kinematic_placement_wakes_a_sleeping_part(resting):
    m, d = resting.model, resting.data
    body = resting.conductor_bodies[0]
    adr = m.jnt_qposadr[m.body_jntadr[body]]
    d.qpos[adr + 2] += 0.005
    z_lifted = d.qpos[adr + 2]
    for _ in range(300):
        mujoco.mj_step(m, d)
    fall = z_lifted - d.xpos[body][2]
    assert fall == pytest.approx(0.5 * 9.81 * 0.03**2, rel=0.05)  # free fall for 30 ms


def test_sleep_can_be_turned_off():
    scene = build_scene(SceneConfig(n_conductors=1, physics=PhysicsConfig(sleep=False)))
    for _ in range(8000):
        mujoco.mj_step(scene.model, scene.data)
    assert not _asleep(scene, 0)
    assert np.all(scene.data.tree_asleep < 0)


def _run(scene, seconds: float) -> None:
    for _ in range(round(seconds / scene.model.opt.timestep)):
        scene.gravity_hold_arm()
        mujoco.mj_step(scene.model, scene.data)


def test_still_platform_sleeps_with_its_seated_part_and_a_command_wakes_it():
    """A seated part touches the platform; before the platform could sleep, every seated part
    stayed awake and a still cell's step grew ~10x with 6 of them."""
    scene = build_scene(SceneConfig(n_conductors=1))
    m, d = scene.model, scene.data
    seat_conductor(scene, 0, 0)
    _run(scene, 1.2)
    platform = m.body(names.STEWART + "platform").id
    tree = m.body_treeid[platform]
    assert d.tree_asleep[tree] >= 0 and _asleep(scene, 0)
    servo = StewartServo.from_model(m, built_geometry(scene.config.stewart)[0], names.STEWART)
    legs = [m.jnt_qposadr[m.actuator_trnid[a, 0]] for a in servo.actuator_ids]
    z0 = d.xpos[platform][2]
    goal = d.ctrl[list(servo.actuator_ids)] + 1e-3
    servo.command_strokes(d, goal)
    _run(scene, 0.01)
    assert d.tree_asleep[tree] < 0 and not _asleep(scene, 0)  # the seated part moves with it
    _run(scene, 1.5)
    # It settles before it sleeps again: within 0.1 um of the command (0.05 measured); at
    # MuJoCo's default tolerance it froze 4.3 um short.
    assert np.max(np.abs(d.qpos[legs] - goal)) < 1e-7
    assert d.xpos[platform][2] - z0 > 0.9e-3
    assert d.tree_asleep[tree] >= 0
