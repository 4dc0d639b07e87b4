"""The transit step (serpar.sim.transit_step): the cell steps at 0.25 ms only while nothing can
reach the plate or the tray, comes back to 0.1 ms before anything can, and leaves a carried
part where the fine step leaves it."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.controllers.arm_controller import controller_config
from serpar.controllers.cell_runtime import CellRuntime
from serpar.errors import ConfigError
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.arm_changes import ArmPlantChanges
from serpar.sim.poses import GRASP_HEIGHT, put_in_hand, solve_tcp_pose
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.seat_lock import PLATE_BODY
from serpar.sim.transit_step import restagger
from serpar.tasks.hole_cycle import HAND_DOWN, TRAVEL_SPEED, inspect_rotation
from serpar.tasks.motions import move_tcp

INSPECTION = np.array([0.35, -0.17, 0.36])
ABOVE_PLATE = np.array([0.60, 0.0, 0.40])


def _carry(transit: bool) -> dict[str, np.ndarray]:
    """A part squeezed in the pads, carried at travel speed to the inspection point and on to
    above the plate: the TCP per period, whether each period ran at the transit step, and the
    part's pose in the hand at both arrivals."""
    scene = build_scene(SceneConfig(n_conductors=1))
    m, d = scene.model, scene.data
    d.qpos[scene.arm_qpos_adr] = solve_tcp_pose(scene, np.array([0.45, 0.15, 0.40]), rotation=HAND_DOWN)
    put_in_hand(scene, 0, GRASP_HEIGHT)
    mujoco.mj_forward(m, d)
    rt = CellRuntime.create(scene, controller_config(noise=False), seed=0, transit=transit)
    rt.gripper.grasp(20.0)
    rt.run(0.6)  # the squeeze settles; the just-built platform settles and falls asleep
    tcp, hand, part = m.site("arm/tcp").id, m.body("arm/hand").id, int(scene.conductor_bodies[0])
    path, coarse = [], []
    rt.observers.append(lambda r: (path.append(d.site_xpos[tcp].copy()),
                                   coarse.append(r.transit is not None and r.transit.transit)))

    def in_hand() -> np.ndarray:
        rot = d.xmat[hand].reshape(3, 3)
        return np.concatenate([(d.xpos[part] - d.xpos[hand]) @ rot, (rot.T @ d.xmat[part].reshape(3, 3)).ravel()])

    move_tcp(rt, INSPECTION, inspect_rotation(), speed=TRAVEL_SPEED, settle_s=0.1)
    at_inspection, tcp_at_inspection = in_hand(), d.site_xpos[tcp].copy()
    move_tcp(rt, ABOVE_PLATE, HAND_DOWN, speed=TRAVEL_SPEED, settle_s=0.1)
    return {"path": np.array(path), "coarse": np.array(coarse), "at_inspection": at_inspection,
            "tcp_at_inspection": tcp_at_inspection, "above_plate": in_hand(), "tcp_end": d.site_xpos[tcp].copy()}


@pytest.fixture(scope="module")
def carried():
    return _carry(False), _carry(True)


def test_the_carry_runs_at_the_transit_step(carried):
    fine, transit = carried
    assert not fine["coarse"].any()
    assert transit["coarse"].all()


def test_the_part_sits_in_the_grip_where_the_fine_step_leaves_it(carried):
    fine, transit = carried
    for where in ("at_inspection", "above_plate"):
        position_um = np.abs(fine[where][:3] - transit[where][:3]).max() * 1e6
        rotation_urad = np.abs(fine[where][3:] - transit[where][3:]).max() * 1e6
        assert position_um < 0.2 and rotation_urad < 5, (where, position_um, rotation_urad)


def test_the_arm_arrives_where_the_fine_step_arrives(carried):
    """At each arrival (after the 0.1 s settle) within 3 um; on the way the first-order
    integration lead differs (up to ~0.15 mm at 0.8 m/s; the fine step is itself ~40 um off a
    0.05 ms reference there)."""
    fine, transit = carried
    assert np.linalg.norm(fine["tcp_at_inspection"] - transit["tcp_at_inspection"]) < 3e-6
    assert np.linalg.norm(fine["tcp_end"] - transit["tcp_end"]) < 3e-6
    on_the_way = np.linalg.norm(fine["path"] - transit["path"], axis=1).max()
    assert on_the_way < 0.3e-3


def test_anything_near_the_plate_brings_back_the_fine_step():
    scene = build_scene(SceneConfig(n_conductors=1))
    rt = CellRuntime.create(scene, controller_config(noise=False), seed=0)
    rt.run(0.6)  # the platform settles and falls asleep
    assert rt.transit is not None and rt.transit.transit
    assert scene.model.opt.timestep == pytest.approx(2.5e-4) and rt.arm.substeps == 4
    plate = scene.data.xpos[scene.model.body(PLATE_BODY).id].copy()
    move_tcp(rt, plate + [0.0, 0.0, 0.02], HAND_DOWN, speed=0.3, settle_s=0.02)
    assert not rt.transit.transit
    assert rt.scene.model.opt.timestep == pytest.approx(1e-4) and rt.arm.substeps == 10


def test_a_delayed_plant_keeps_the_fine_step():
    """A delay kept as a history of steps (a diagnosed actuation delay) would change with the step."""
    scene = build_scene(SceneConfig(n_conductors=0, arm_plant=ArmPlantChanges(actuation_delay=5e-4)))
    rt = CellRuntime.create(scene, controller_config(noise=False), seed=0)
    rt.run(0.05)
    assert rt.transit is not None and not rt.transit.available
    assert not rt.transit.transit and scene.model.opt.timestep == pytest.approx(1e-4)


@pytest.mark.parametrize("h", [5e-5, 3e-4])
def test_a_transit_step_outside_its_range_is_named(h):
    with pytest.raises(ConfigError, match="transit_timestep"):
        PhysicsConfig(transit_timestep=h)


def _wheel() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """A wheel on a hinge driven by a constant torque: a constant acceleration of 2 rad/s²."""
    m = mujoco.MjModel.from_xml_string("""
    <mujoco><option gravity="0 0 0" integrator="implicitfast"/>
      <worldbody><body><joint name="hinge" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="1" diaginertia="0.5 0.5 0.5"/></body></worldbody>
      <actuator><motor joint="hinge"/></actuator></mujoco>""")
    d = mujoco.MjData(m)
    d.ctrl[0], d.qvel[0] = 1.0, 0.3
    return m, d


@pytest.mark.parametrize("h1, h2", [(1e-4, 2.5e-4), (2.5e-4, 1e-4)])
@pytest.mark.parametrize("restaggered", [True, False])
def test_a_change_of_step_leaves_the_sampled_acceleration_true(h1, h2, restaggered):
    """Positions sampled every 1 ms across a switch of the step imply the acceleration the
    torque gives only with the velocity re-staggered (restagger); without it they read
    (h2 - h1) / (2 T) off: +7.5 % going to the transit step, -7.5 % coming back. An arm's
    recorded encoders showed that as a one-sample spike of up to 1 N m against its torque
    sensors at every switch of a nominal episode."""
    m, d = _wheel()
    period, q = 1e-3, []
    for h in (h1, h1, h2):
        if h != m.opt.timestep:
            old, m.opt.timestep = m.opt.timestep, h
            if restaggered:
                restagger(m, d, old, h)
        q.append(d.qpos[0])
        for _ in range(round(period / h)):
            mujoco.mj_step(m, d)
    q.append(d.qpos[0])
    implied = (q[3] - 2 * q[2] + q[1]) / period**2
    expected = 2.0 if restaggered else 2.0 * (1 + (h2 - h1) / (2 * period))
    assert implied == pytest.approx(expected, rel=1e-6)
