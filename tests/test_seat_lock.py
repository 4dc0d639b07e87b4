"""A scored, seated part is welded to the plate (sim.seat_lock): it keeps the pose it seated
at while the platform moves, it stops touching the plate (that was its cost), and everything
else still collides with it."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from controllers.stewart_servo import StewartServo
from sim import collision, names
from sim.errors import SimError
from sim.scene import SceneConfig, build_scene
from sim.seat_lock import PLATE_BODY, is_locked, lock_seated
from sim.stewart import built_geometry
from tasks.vision_scenes import seat_conductor


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


def _plate_contacts(scene, k: int) -> int:
    m, d = scene.model, scene.data
    body, n = scene.conductor_bodies[k], 0
    for c in d.contact[:d.ncon]:
        bodies = {m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]}
        if body in bodies and any(m.body(b).name.startswith(names.PLATE) for b in bodies):
            n += 1
    return n


@pytest.fixture(scope="module")
def seated():
    """Conductor 0 settled 0.3 s in hole 0 (a far corner, 35 mm from the plate centre)."""
    scene = build_scene(SceneConfig(n_conductors=2))
    seat_conductor(scene, 0, 0)
    _run(scene, 0.3)
    return scene


def test_locking_holds_the_seated_pose_while_the_platform_moves(seated):
    scene = seated
    m, d = scene.model, scene.data
    assert _plate_contacts(scene, 0) > 0 and not is_locked(m, d, 0)
    lock_seated(m, d, 0)
    assert is_locked(m, d, 0) and not is_locked(m, d, 1)
    points0 = _points_in_plate(scene, 0)
    servo = StewartServo.from_model(m, built_geometry(scene.config.stewart)[0], names.STEWART)
    plate = m.body(PLATE_BODY).id
    z0, worst = d.xpos[plate][2], 0.0
    servo.command_strokes(d, d.ctrl[list(servo.actuator_ids)] + 3e-3)  # a 3 mm lift
    for _ in range(100):
        _run(scene, 0.005)
        worst = max(worst, float(np.max(np.linalg.norm(_points_in_plate(scene, 0) - points0, axis=1))))
    assert d.xpos[plate][2] - z0 > 2.5e-3  # it did move
    assert _plate_contacts(scene, 0) == 0  # the seat and bore contacts are gone
    assert worst < 0.5e-6, f"locked part moved {worst * 1e6:.3f} um against the plate"


def test_a_locked_part_still_meets_the_hand_and_other_parts_but_not_the_plate():
    def touches(a: tuple[int, int], b: tuple[int, int]) -> bool:
        return bool((a[0] & b[1]) or (b[0] & a[1]))

    locked = collision.SEATED_LOCKED
    scene = build_scene(SceneConfig(n_conductors=1))
    m = scene.model
    kinds = {"plate": [], "hand": [], "part": []}
    for g in range(m.ngeom):
        body = m.body(m.geom_bodyid[g]).name
        bits = (int(m.geom_contype[g]), int(m.geom_conaffinity[g]))
        if bits == (0, 0):
            continue
        if body.startswith(names.PLATE):
            kinds["plate"].append(bits)  # bore facets, plate top, seat box, the fixture below
        elif body.startswith(names.ARM) and "finger" in body:
            kinds["hand"].append(bits)
        elif body.startswith(names.conductor(0)):
            kinds["part"].append(bits)
    assert kinds["plate"] and kinds["hand"] and kinds["part"]
    assert not any(touches(locked, b) for b in kinds["plate"])
    assert all(touches(locked, b) for b in kinds["hand"] + kinds["part"])
    # MuJoCo's broad phase filters body pairs by the compiled per-body bits: a locked part and
    # the plate must fail it too, or the plate's 600-geom tree is walked for it every step.
    plate = m.body(PLATE_BODY).id
    part = int(scene.conductor_bodies[0])
    lock_seated(m, scene.data, 0)
    assert not touches((int(m.body_contype[part]), int(m.body_conaffinity[part])),
                       (int(m.body_contype[plate]), int(m.body_conaffinity[plate])))


def test_locking_an_unknown_part_is_named():
    scene = build_scene(SceneConfig(n_conductors=1))
    with pytest.raises(SimError, match="seat_lock5"):
        lock_seated(scene.model, scene.data, 5)
