"""The gripper picks a conductor out of the tray by physics and carries it without it
sliding in the pads; an unstable integration is caught and named."""

import numpy as np
import pytest

from serpar.checks.vision_inhand_scenes import true_in_hand
from serpar.controllers.arm_controller import controller_config
from serpar.controllers.cell_runtime import CellRuntime
from serpar.errors import UnstableSimulation
from serpar.sim import names
from serpar.sim.poses import GRASP_HEIGHT
from serpar.sim.scene import SceneConfig, build_scene
from serpar.tasks.motions import move_tcp, tcp_pose

GRASP_ROT = np.array([[-1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])  # TCP z down, fingers close along y


def _runtime(n_conductors: int) -> CellRuntime:
    scene = build_scene(SceneConfig(n_conductors=n_conductors))
    rt = CellRuntime.create(scene, controller_config(noise=True), seed=0)
    rt.arm.update(scene.model, scene.data)
    return rt


@pytest.fixture(scope="module")
def picked():
    """Conductor 14 (tray interior: neighbours on all sides) picked and carried 0.5 m."""
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
    return lifted, np.max(np.linalg.norm(after - before, axis=1)), carried


def test_part_lifted_out_of_its_pocket(picked):
    lifted, _, _ = picked
    assert abs(lifted[2] - 0.03) < 1e-4 and np.linalg.norm(lifted[:2]) < 1e-4


def test_neighbours_undisturbed(picked):
    _, moved, _ = picked
    assert moved < 1e-5


def test_part_does_not_slide_mm_in_the_pads_in_transit(picked):
    _, _, carried = picked
    # 0.5 m at 0.5 m/s: MuJoCo's friction damper lets it slide ~ speed / (2 / timeconst);
    # with the old 0.01 s pad time constant this was ~1.5 mm.
    assert np.linalg.norm(carried) < 1e-4


@pytest.mark.xfail(strict=True, reason="pad slip is ~70 um per 0.5 m transit at the stable pad "
                   "time constant (5 dt); the task needs < 20 um between inspection and insertion")
def test_part_slides_less_than_the_task_needs(picked):
    _, _, carried = picked
    assert np.linalg.norm(carried) < 2e-5


def test_blow_up_is_named():
    rt = _runtime(0)
    rt.scene.data.qvel[0] = np.nan
    with pytest.raises(UnstableSimulation, match="t = "):
        rt.step()
