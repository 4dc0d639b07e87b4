"""The gripper picks a conductor out of the tray by physics and carries it without it
sliding in the pads, also under an insertion's 5 N axial push; an unstable integration is caught
and named."""

import mujoco
import numpy as np
import pytest

from serpar.checks.vision_inhand_scenes import true_in_hand
from serpar.controllers.arm_controller import controller_config
from serpar.controllers.cell_runtime import CellRuntime
from serpar.controllers.gripper_servo import GRASP_SPEED
from serpar.errors import ConfigError, UnstableSimulation
from serpar.sim import names
from serpar.sim.arm import FINGER_BODIES, PAD_CONTYPE, PAD_GEOMS
from serpar.sim.physics import PhysicsConfig
from serpar.sim.poses import GRASP_HEIGHT
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.seat_lock import lock_seated
from serpar.tasks.motions import move_tcp, tcp_pose

GRASP_ROT = np.array([[-1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])  # TCP z down, fingers close along y


def _runtime(n_conductors: int) -> CellRuntime:
    scene = build_scene(SceneConfig(n_conductors=n_conductors))
    rt = CellRuntime.create(scene, controller_config(noise=True), seed=0)
    rt.arm.update(scene.model, scene.data)
    return rt


def _in_pads(rt: CellRuntime, k: int) -> np.ndarray:
    """Conductor k's shoulder in the left finger's frame, from the midpoint between the fingers:
    where the part sits in the pads (the fingers ride on the gripper's axial spring, so the
    TCP frame of true_in_hand also sees that spring's deflection)."""
    m, d = rt.scene.model, rt.scene.data
    left, right = (m.body(names.ARM + b).id for b in FINGER_BODIES)
    rot = d.xmat[left].reshape(3, 3)
    return rot.T @ (d.site(f"{names.conductor(k)}shoulder").xpos - (d.xpos[left] + d.xpos[right]) / 2)


@pytest.fixture(scope="module")
def carried_runtime():
    """Conductor 14 (tray interior: neighbours on all sides) picked and carried 0.5 m; the
    runtime afterwards, holding it."""
    rt = _runtime(36)
    d = rt.scene.data
    k = 14
    shoulder = d.site(f"{names.conductor(k)}shoulder").xpos.copy()  # test set-up, not vision
    others = [j for j in range(36) if j != k]
    before = np.array([d.site(f"{names.conductor(j)}shoulder").xpos for j in others])
    rt.gripper.open_to(rt.scene.diameters.bodies[k] + 1.5e-3)
    move_tcp(rt, shoulder + [0, 0, GRASP_HEIGHT + 0.015], GRASP_ROT)
    move_tcp(rt, shoulder + [0, 0, GRASP_HEIGHT], GRASP_ROT, speed=0.05)
    rt.gripper.grasp(20.0)
    rt.run(0.3)
    in_hand_at_grasp = true_in_hand(rt.scene, k).tip.copy()
    move_tcp(rt, shoulder + [0, 0, GRASP_HEIGHT + 0.03], GRASP_ROT, speed=0.05)
    lifted = d.site(f"{names.conductor(k)}shoulder").xpos - shoulder
    after = np.array([d.site(f"{names.conductor(j)}shoulder").xpos for j in others])
    move_tcp(rt, tcp_pose(rt)[0] + [0.0, 0.0, 0.1], GRASP_ROT, speed=0.5)  # clear of the plate
    move_tcp(rt, tcp_pose(rt)[0] + [-0.15, -0.37, 0.0], GRASP_ROT, speed=0.5)
    carried = true_in_hand(rt.scene, k).tip - in_hand_at_grasp
    return rt, (lifted, np.max(np.linalg.norm(after - before, axis=1)), carried)


@pytest.fixture(scope="module")
def picked(carried_runtime):
    return carried_runtime[1]


def test_part_lifted_out_of_its_pocket(picked):
    lifted, _, _ = picked
    assert abs(lifted[2] - 0.03) < 1e-4 and np.linalg.norm(lifted[:2]) < 1e-4


def test_neighbours_undisturbed(picked):
    _, moved, _ = picked
    assert moved < 1e-5


def test_part_does_not_slide_mm_in_the_pads_in_transit(picked):
    _, _, carried = picked
    # With the old 0.01 s pad time constant this was ~1.5 mm.
    assert np.linalg.norm(carried) < 1e-4


def test_part_slides_less_than_the_task_needs(picked):
    """Issue 27: the task needs < 20 um between in-hand inspection and insertion. The pads'
    friction rows used to drift at Jdot*qvel * (1/b - dt/2), ~70 um per 0.5 m/s transit at
    b = 2/(5 dt); with PhysicsConfig.grip_friction_damping (b = 1.5/dt) it is ~6 um."""
    _, _, carried = picked
    assert np.linalg.norm(carried) < 2e-5


def test_the_pads_grip_through_their_pairs_only(carried_runtime):
    """Every pad contact on the held part comes from its explicit pair (the solreffriction
    is the pair's: no duplicate contact from the collision bits), four of them (two line ends
    per flat pad on the cylinder), and the squeeze reaches the part."""
    rt, _ = carried_runtime
    m, d = rt.scene.model, rt.scene.data
    pads = {m.geom(names.ARM + p).id for p in PAD_GEOMS}
    body = m.geom(f"{names.conductor(14)}body").id
    found = [c for c in d.contact[:d.ncon] if {c.geom1, c.geom2} & pads and body in (c.geom1, c.geom2)]
    assert len(found) == 4
    f6 = np.zeros(6)
    normal = 0.0
    physics = PhysicsConfig()  # the pair's damping: the transit step's while the hand is away from all
    expected = physics.transit_grip_solreffriction if rt.transit and rt.transit.transit else physics.grip_solreffriction
    for c in found:
        np.testing.assert_allclose(c.solreffriction, expected)
        i = next(i for i in range(d.ncon) if d.contact[i].efc_address == c.efc_address)
        mujoco.mj_contactForce(m, d, i, f6)
        normal += f6[0]
    assert normal == pytest.approx(2 * 20.0, rel=0.05)  # 20 N squeeze per pad


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["push", "pull"])
def test_part_holds_in_the_pads_under_a_5N_axial_load(carried_runtime, sign):
    """An insertion's 5 N push along the held part's axis (the hole pushing its tip up into
    the grip; and the same pulling it out) for 0.5 s: the part moves < 20 um in the pads
    (measured ~0.01 um). The hand frame sees it move 0.25 mm: that is the gripper's axial
    spring (grip_compliance, 20 000 N/m), which carries the fingers, not slip."""
    rt, _ = carried_runtime
    d = rt.scene.data
    b = rt.scene.conductor_bodies[14]
    rt.run(0.05)
    in_pads, in_hand = _in_pads(rt, 14), true_in_hand(rt.scene, 14).tip.copy()
    axis = d.xmat[b].reshape(3, 3)[:, 2].copy()  # body up, journal down
    d.xfrc_applied[b, :3] = sign * 5.0 * axis
    try:
        rt.run(0.5)
        slid = _in_pads(rt, 14) - in_pads
        spring = true_in_hand(rt.scene, 14).tip - in_hand
    finally:
        d.xfrc_applied[b] = 0.0
    rt.run(0.1)
    assert np.linalg.norm(slid) < 2e-5
    assert np.linalg.norm(spring) == pytest.approx(5.0 / 20000.0, rel=0.05)


def test_pad_pairs_cover_every_conductor_and_survive_a_lock():
    """One pair per pad and conductor body, with the pads' own friction damping, and the pads'
    contype (read back) keeps MuJoCo from making those contacts a second time; locking a
    seated part into the plate keeps its pairs (the hand still meets it)."""
    scene = build_scene(SceneConfig(n_conductors=3))
    m = scene.model
    for pad in PAD_GEOMS:
        g = m.geom(names.ARM + pad)
        assert g.contype[0] == PAD_CONTYPE and g.conaffinity[0] == 1
        assert not (g.contype[0] & m.geom(f"{names.conductor(0)}body").conaffinity[0])

    def paired(model):
        return {(model.geom(model.pair_geom1[i]).name, model.geom(model.pair_geom2[i]).name): i
                for i in range(model.npair)}

    want = {(names.ARM + pad, f"{names.conductor(k)}body") for pad in PAD_GEOMS for k in range(3)}
    assert set(paired(m)) == want
    np.testing.assert_allclose(m.pair_solreffriction, [PhysicsConfig().grip_solreffriction] * 6)
    lock_seated(scene, 1)
    assert set(paired(scene.model)) == want
    np.testing.assert_allclose(scene.model.pair_solreffriction, m.pair_solreffriction)


def test_pad_friction_damping_stays_below_the_stability_limit():
    assert PhysicsConfig().grip_solreffriction == (0.0, -1.5 / PhysicsConfig().timestep)
    for bad in (0.0, 2.0, 2.5):
        with pytest.raises(ConfigError, match="grip_friction_damping"):
            PhysicsConfig(grip_friction_damping=bad)


def test_blow_up_is_named():
    rt = _runtime(0)
    rt.scene.data.qvel[0] = np.nan
    with pytest.raises(UnstableSimulation, match="t = "):
        rt.step()


def _grasp_off_centre(offset: float) -> tuple[CellRuntime, float, float]:
    """Conductor 0 grasped with the TCP ``offset`` off its axis along the closing direction:
    the runtime after the grasp, the fastest finger and the part's fastest speed during it."""
    rt = _runtime(1)
    m, d = rt.scene.model, rt.scene.data
    shoulder = d.site(f"{names.conductor(0)}shoulder").xpos.copy()  # test set-up, not vision
    grasp = shoulder + [0, offset, GRASP_HEIGHT]  # the fingers close along y
    rt.gripper.open_to(rt.scene.diameters.bodies[0] + 1.5e-3)
    move_tcp(rt, grasp + [0, 0, 0.015], GRASP_ROT)
    move_tcp(rt, grasp, GRASP_ROT, speed=0.05)
    fingers = [m.joint(names.ARM + j).dofadr[0] for j in ("finger_left", "finger_right")]
    part = m.body_dofadr[rt.scene.conductor_bodies[0]]
    speeds: list[tuple[float, float]] = []
    rt.observers.append(lambda r: speeds.append((float(np.abs(d.qvel[fingers]).max()),
                                                float(np.linalg.norm(d.qvel[part:part + 3])))))
    rt.gripper.grasp(20.0)
    rt.run(0.25)
    finger, moved = np.max(speeds, axis=0)
    return rt, finger, moved


@pytest.mark.parametrize("offset", [0.0, 3e-4, 4.5e-4], ids=["centred", "0.3 mm off", "0.45 mm off"])
def test_a_grasp_closes_at_the_hands_speed_and_does_not_knock_the_part(offset):
    """Within the pocket's play (the journal has 0.45 mm each way) the jaw closes at GRASP_SPEED
    until the pads are blocked, then squeezes: no finger moves faster than the hand closes (an
    instant 20 N squeeze threw them at the part at up to 0.9 m/s, knocked an off-centre part
    across its pocket at ~1 m/s and blew up the integration), the part is pushed at most at a
    finger's speed, and the squeeze then holds it."""
    rt, finger, moved = _grasp_off_centre(offset)
    assert finger < 0.75 * GRASP_SPEED  # per finger: half the jaw's speed, with the PD's overshoot
    assert moved < 0.75 * GRASP_SPEED
    assert rt.gripper.blocked
    assert rt.gripper.width(rt.scene.data) == pytest.approx(rt.scene.diameters.bodies[0], abs=1e-5)


def test_a_part_pushed_against_its_pockets_wall_is_grasped_without_a_slam():
    """0.6 mm off, beyond the pocket's play: the first pad tilts the part against the pocket's
    wall, the jaw reads blocked before the second pad arrives, and the squeeze rises over
    SQUEEZE_RISE while the part straightens: no finger, and not the part, moves faster than
    the jaw closes (measured 0.032 and 0.028 m/s; the instant squeeze reached 0.29 m/s and
    blew this grasp up), and the part ends held."""
    rt, finger, moved = _grasp_off_centre(6e-4)
    assert finger < GRASP_SPEED and moved < GRASP_SPEED
    assert rt.gripper.blocked
    assert rt.gripper.width(rt.scene.data) == pytest.approx(rt.scene.diameters.bodies[0], abs=1e-5)
