"""The cell's arm joints' dry friction (MuJoCo ``frictionloss``) acts as Coulomb friction: while a
joint moves, its friction opposes the motion, however fast other torques decelerate it. It does
with the cell's stiff friction row (``PhysicsConfig.arm_friction_timeconst`` 0.5 ms); with MuJoCo's
default 20 ms it does not."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim.arm import ACTUATOR_NAMES, JOINT_NAMES, PANDA_COULOMB_FRICTION
from serpar.sim.physics import PhysicsConfig
from serpar.sim.scene import SceneConfig, build_scene

J4 = 3


def _friction_while_braking(brake_nm: float, physics: PhysicsConfig
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Joint 4 set moving at 0.06 rad/s and braked by ``brake_nm`` beyond gravity, through zero
    speed and back the other way: its velocity and frictionloss force at every physics step."""
    friction = tuple(0.3 * f for f in PANDA_COULOMB_FRICTION)
    scene = build_scene(SceneConfig(n_conductors=0, arm_joint_friction=friction, physics=physics))
    m, d = scene.model, scene.data
    dofs = [m.jnt_dofadr[m.joint("arm/" + j).id] for j in JOINT_NAMES]
    acts = [m.actuator("arm/" + a).id for a in ACTUATOR_NAMES]
    d.qvel[dofs[J4]] = 0.06
    v, f = [], []
    for _ in range(400):  # 40 ms
        mujoco.mj_forward(m, d)
        d.ctrl[acts] = d.qfrc_bias[dofs]
        d.ctrl[acts[J4]] -= brake_nm
        mujoco.mj_step(m, d)
        rows = (d.efc_type[:d.nefc] == mujoco.mjtConstraint.mjCNSTR_FRICTION_DOF) & (
            d.efc_id[:d.nefc] == dofs[J4])
        v.append(d.qvel[dofs[J4]])
        f.append(d.efc_force[:d.nefc][rows].sum())
    return np.array(v), np.array(f)


def _pushes_it_on(physics: PhysicsConfig) -> float:
    """The largest friction along the motion while the braked joint moves [N m]."""
    v, f = _friction_while_braking(5.0, physics)
    assert v[0] > 0.05 and v[-1] < -0.05  # braked through zero and driven back
    moving = np.abs(v) > 1e-3
    # efc_force of a dof friction opposes +v when negative: it must never share v's sign
    return float(np.max(f[moving] * np.sign(v[moving])))


def test_the_cells_friction_never_pushes_a_braked_joint_on() -> None:
    assert PhysicsConfig().arm_friction_timeconst == 5e-4
    assert _pushes_it_on(PhysicsConfig()) <= 1e-9


def test_mujocos_default_soft_friction_row_pushes_a_braked_joint_on() -> None:
    """The artifact the cell's time constant removes, so that the test above can fail."""
    assert _pushes_it_on(PhysicsConfig(arm_friction_timeconst=0.02)) > 0.05


def test_a_friction_row_softer_than_the_step_is_named() -> None:
    with pytest.raises(ConfigError, match="arm_friction_timeconst"):
        PhysicsConfig(arm_friction_timeconst=1e-4)  # under twice the 0.25 ms transit step
