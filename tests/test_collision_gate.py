"""The collision gate (serpar.sim.collision_gate) takes the plate and the tray out of the broad
phase only while nothing can reach them: the cell's trajectory is bit-identical with and without
it, and a part falling onto the plate finds the plate there."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.controllers.arm_controller import controller_config
from serpar.controllers.cell_runtime import GATED_BODIES, CellRuntime
from serpar.sim import names
from serpar.sim.collision_gate import CollisionGate
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.seat_lock import PLATE_BODY
from serpar.tasks.hole_cycle import HAND_DOWN
from serpar.tasks.motions import move_tcp


def _runtime(gate: bool, n_conductors: int = 2) -> CellRuntime:
    scene = build_scene(SceneConfig(n_conductors=n_conductors))
    return CellRuntime.create(scene, controller_config(noise=False), seed=0, gate=gate, transit=False)


def _hand_to_the_plate_and_back(rt: CellRuntime) -> np.ndarray:
    """The hand from its home pose down to 20 mm above the plate centre and up again."""
    d = rt.scene.data
    plate = d.xpos[rt.scene.model.body(PLATE_BODY).id].copy()
    rt.run(0.05)
    move_tcp(rt, plate + [0.0, 0.0, 0.12], HAND_DOWN, speed=0.5, settle_s=0.0)
    move_tcp(rt, plate + [0.0, 0.0, 0.02], HAND_DOWN, speed=0.2, settle_s=0.02)
    move_tcp(rt, plate + [0.0, 0.0, 0.15], HAND_DOWN, speed=0.5, settle_s=0.0)
    return np.concatenate([d.qpos, d.qvel, d.qacc_warmstart])


def test_the_gate_changes_no_bit_of_the_trajectory():
    gated, plain = _runtime(True), _runtime(False)
    state = _hand_to_the_plate_and_back(gated)
    assert gated.gate is not None and gated.gate.switches >= 3  # off, on near the plate, off again
    assert np.array_equal(state, _hand_to_the_plate_and_back(plain))


def test_both_groups_are_out_while_the_arm_is_away_and_the_plate_comes_in_near_the_hand():
    rt = _runtime(True)
    rt.run(0.02)
    assert [g.on for g in rt.gate.groups] == [False, False]  # home pose: nothing near either
    d = rt.scene.data
    plate = d.xpos[rt.scene.model.body(PLATE_BODY).id].copy()
    move_tcp(rt, plate + [0.0, 0.0, 0.02], HAND_DOWN, speed=0.3, settle_s=0.02)
    assert rt.gate.groups[0].on and not rt.gate.groups[1].on


def _drop_part_on_plate(gate: bool) -> tuple[np.ndarray, int]:
    """Conductor 0 let go 30 mm above the plate top, away from the bores; the arm holds."""
    rt = _runtime(gate, n_conductors=1)
    m, d = rt.scene.model, rt.scene.data
    rt.run(0.02)
    plate = d.xpos[m.body(PLATE_BODY).id].copy()
    body = int(rt.scene.conductor_bodies[0])
    adr = m.jnt_qposadr[m.body_jntadr[body]]
    d.qpos[adr:adr + 3] = plate + np.array([0.0021, 0.0013, 0.03])  # between bores, upright
    d.qpos[adr + 3:adr + 7] = [1.0, 0.0, 0.0, 0.0]
    d.qvel[m.body_dofadr[body]:m.body_dofadr[body] + 6] = [0.0, 0.0, -0.5, 0.0, 0.0, 0.0]
    mujoco.mj_forward(m, d)
    rt.reset_health()
    rt.run(0.3)
    touching = sum(1 for c in d.contact[:d.ncon]
                   if body in (m.geom_bodyid[c.geom1], m.geom_bodyid[c.geom2]))
    return d.xpos[body].copy(), touching


def test_a_part_thrown_onto_the_plate_rests_on_it_as_without_the_gate():
    gated, touching = _drop_part_on_plate(True)
    plain, _ = _drop_part_on_plate(False)
    assert touching > 0
    assert np.array_equal(gated, plain)


def test_the_tray_ignores_sleeping_parts_but_the_moving_plate_does_not():
    scene = build_scene(SceneConfig(n_conductors=2))
    m, d = scene.model, scene.data
    for _ in range(3000):  # the tray parts fall asleep
        scene.gravity_hold_arm()
        mujoco.mj_step(m, d)
    gate = CollisionGate(m, d, GATED_BODIES)
    gate.update(d)
    gate.update(d)
    assert [g.static for g in gate.groups] == [False, True]
    assert not gate.groups[1].on  # the parts in its pockets are asleep
    body = int(scene.conductor_bodies[0])
    d.qvel[m.body_dofadr[body]] = 1e-3  # one part awake in its pocket
    mujoco.mj_step(m, d)
    gate.update(d)
    assert gate.groups[1].on


def test_a_gate_on_an_unknown_body_names_it():
    scene = build_scene(SceneConfig(n_conductors=0))
    with pytest.raises(KeyError, match="nonexistent"):
        CollisionGate(scene.model, scene.data, (names.PLATE + "nonexistent",))
