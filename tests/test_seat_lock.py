"""A scored, seated part becomes part of the plate (serpar.sim.seat_lock): it keeps the pose it seated
at, the rest of the state carries over the recompile, it stops touching the plate, and the
hand and loose parts still collide with it."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.checks.vision_scenes import seat_conductor
from serpar.controllers.stewart_servo import StewartServo
from serpar.errors import SerparError
from serpar.sim import names
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.seat_lock import PLATE_BODY, is_locked, lock_seated
from serpar.sim.stewart import built_geometry


def _run(scene, seconds: float) -> None:
    for _ in range(round(seconds / scene.model.opt.timestep)):
        scene.gravity_hold_arm()
        mujoco.mj_step(scene.model, scene.data)


def _points_in_plate(scene, k: int) -> np.ndarray:
    """The part's tip and shoulder in the plate frame (a tilt shows as a point moving)."""
    m, d, plate = scene.model, scene.data, scene.model.body(PLATE_BODY).id
    rot = d.xmat[plate].reshape(3, 3)
    sites = [m.site(f"{names.conductor(k)}{s}").id for s in ("tip", "shoulder")]
    return (d.site_xpos[sites] - d.xpos[plate]) @ rot


def _contacts(scene, k: int, other: str) -> int:
    """Contacts between conductor k and bodies whose names start with `other`."""
    m, d = scene.model, scene.data
    body, n = scene.conductor_bodies[k], 0
    for c in d.contact[:d.ncon]:
        bodies = {int(m.geom_bodyid[c.geom1]), int(m.geom_bodyid[c.geom2])}
        if body in bodies and any(m.body(b).name.startswith(other) for b in bodies - {body}):
            n += 1
    return n


@pytest.fixture(scope="module")
def seated():
    """Conductor 0 settled 0.3 s in hole 0 (a far corner, 35 mm from the plate centre)."""
    scene = build_scene(SceneConfig(n_conductors=2))
    seat_conductor(scene, 0, 0)
    _run(scene, 0.3)
    return scene


def test_locking_keeps_the_seated_pose_and_the_state_while_the_platform_moves(seated):
    scene = seated
    m, d = scene.model, scene.data
    assert _contacts(scene, 0, names.PLATE) > 0 and not is_locked(scene, 0)
    points0 = _points_in_plate(scene, 0)
    qpos, qvel, ctrl, t = d.qpos.copy(), d.qvel.copy(), d.ctrl.copy(), d.time
    free1 = m.jnt_qposadr[m.body(int(scene.conductor_bodies[1])).jntadr[0]]
    lock_seated(scene, 0)
    assert scene.model is not m and scene.data is not d
    m, d = scene.model, scene.data
    assert is_locked(scene, 0) and not is_locked(scene, 1)
    assert m.nq == len(qpos) - 7 and d.time == t and np.array_equal(d.ctrl, ctrl)
    rest = m.jnt_qposadr[m.body(int(scene.conductor_bodies[1])).jntadr[0]]
    assert np.array_equal(d.qpos[:rest], qpos[:rest])  # arm and legs, before the conductors
    assert np.array_equal(d.qpos[rest:rest + 7], qpos[free1:free1 + 7])  # the other part
    dof_rest = m.jnt_dofadr[m.body(int(scene.conductor_bodies[1])).jntadr[0]]
    assert np.array_equal(d.qvel[:dof_rest], qvel[:dof_rest])
    jump = float(np.max(np.linalg.norm(_points_in_plate(scene, 0) - points0, axis=1)))
    assert jump < 0.1e-6, f"the lock moved the part {jump * 1e6:.3f} um"
    servo = StewartServo.from_model(m, built_geometry(scene.config.stewart)[0], names.STEWART)
    plate = m.body(PLATE_BODY).id
    z0 = d.xpos[plate][2]
    servo.command_strokes(d, d.ctrl[list(servo.actuator_ids)] + 3e-3)  # a 3 mm lift
    _run(scene, 0.5)
    assert d.xpos[plate][2] - z0 > 2.5e-3  # it did move
    assert _contacts(scene, 0, names.PLATE) == 0  # the seat and bore contacts are gone
    drift = float(np.max(np.linalg.norm(_points_in_plate(scene, 0) - points0, axis=1)))
    assert drift < 0.1e-6, f"locked part moved {drift * 1e6:.3f} um against the plate"


def test_a_locked_part_still_meets_a_loose_part():
    """Conductor 1 dropped onto conductor 0's top after 0 was locked rests on it."""
    scene = build_scene(SceneConfig(n_conductors=2))
    seat_conductor(scene, 0, 0)
    _run(scene, 0.1)
    lock_seated(scene, 0)
    m, d = scene.model, scene.data
    top = d.site_xpos[m.site(f"{names.conductor(0)}top").id].copy()
    adr = m.jnt_qposadr[m.body(int(scene.conductor_bodies[1])).jntadr[0]]
    tip_to_origin = d.xpos[scene.conductor_bodies[1]] - d.site_xpos[m.site(f"{names.conductor(1)}tip").id]
    d.qpos[adr:adr + 3] = top + tip_to_origin + np.array([0.0, 0.0, 1e-3])  # its tip 1 mm above the top
    d.qvel[:] = 0
    mujoco.mj_forward(m, d)
    _run(scene, 0.3)
    assert _contacts(scene, 1, names.conductor(0)) > 0
    assert d.xpos[scene.conductor_bodies[1]][2] > top[2]  # it did not fall through


def test_locking_twice_or_an_unknown_part_is_named():
    scene = build_scene(SceneConfig(n_conductors=1))
    with pytest.raises(SerparError, match="conductor 5 out of range"):
        lock_seated(scene, 5)
    lock_seated(scene, 0)
    with pytest.raises(SerparError, match="already locked"):
        lock_seated(scene, 0)
