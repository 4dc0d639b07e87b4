"""Step 6 alone: a journal held above hole 14 (put in the hand kinematically as the initial
condition) is inserted under direct force-position control and the outcome is classified
from the simulator's truth."""

import numpy as np
import pytest

from serpar.controllers.arm_controller import ControlLaw, controller_config
from serpar.controllers.cell_runtime import CellRuntime
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.poses import GRASP_HEIGHT, put_in_hand, solve_tcp_pose
from serpar.sim.scene import SceneConfig, build_scene
from serpar.tasks.episode_config import Outcome
from serpar.tasks.insertion import InsertionConfig, InsertionResult, insert

HOLE = 14


def _insert_with_offset(offset: float) -> InsertionResult:
    scene = build_scene(SceneConfig(n_conductors=1))
    d = scene.data
    seat = d.site_xpos[scene.hole_sites[HOLE]] + [offset, 0.0, GRASP_HEIGHT]
    d.qpos[scene.arm_qpos_adr] = solve_tcp_pose(scene, seat + [0.0, 0.0, 0.003])
    put_in_hand(scene, 0, GRASP_HEIGHT)
    rt = CellRuntime.create(scene, controller_config(noise=True), seed=0)
    rt.gripper.grasp(20.0)
    rt.run(0.3)
    rt.arm.tare()
    rot = d.site(names.ARM + "tcp").xmat.reshape(3, 3).copy()
    return insert(rt, seat, rot, np.array([0.0, 0.0, -1.0]), ControlLaw.FORCE_POSITION, 0, HOLE)


def test_aligned_journal_seats():
    result = _insert_with_offset(0.0)
    assert result.outcome is Outcome.SUCCESS, result.reason
    assert result.depth_shortfall_mm < 0.02 and result.peak_force_n < 20.0
    assert result.insertion_time_s < 2.0


@pytest.mark.parametrize("offset", [5e-4])
def test_journal_beyond_the_chamfer_does_not_enter(offset):
    result = _insert_with_offset(offset)
    assert result.outcome is Outcome.ALIGN_FAIL, result.reason
    assert abs(result.lateral_misalignment_mm - offset * 1e3) < 0.05
    assert result.depth_shortfall_mm > 1.4  # the whole journal stayed out


def test_the_push_ramps_from_the_contact_threshold_to_f_d():
    cfg = InsertionConfig(force_n=5.0, contact_n=1.0, force_ramp_s=0.3)
    assert cfg.push_at(0.0) == pytest.approx(1.0)
    assert cfg.push_at(0.15) == pytest.approx(3.0)
    assert cfg.push_at(0.3) == cfg.push_at(2.0) == 5.0
    assert InsertionConfig(force_ramp_s=0.0).push_at(0.0) == 5.0  # 0: the old step


def test_a_negative_ramp_is_refused():
    with pytest.raises(ConfigError, match="force_ramp_s"):
        InsertionConfig(force_ramp_s=-0.1)
