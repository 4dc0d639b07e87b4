"""Drive friction MuJoCo has no element for (the published sigmoid, a Stribeck fall) and rotor
inertia, from a diagnosis model file into the simulated cell's arm (sim/plants/drive_friction.py,
sim/plants/from_model_file.py): what `serpar sim2real` reruns its updated model with."""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim.arm import PANDA_COULOMB_FRICTION
from serpar.sim.mjcf_export import export_arm_mjcf
from serpar.sim.model_file import read_model_file
from serpar.sim.plants.drive_friction import (
    DriveFriction,
    DriveFrictionLaw,
    gaz_sigmoid_params,
)
from serpar.tasks.episode import build_runtime
from serpar.tasks.episode_config import EpisodeConfig

J = range(1, 8)


def _model_file(tmp_path: Path, effects: dict[str, dict[str, float]]) -> Path:
    path = tmp_path / "drive.model.json"
    path.write_text(json.dumps({"source": "test", "kind": "arm_dynamics", "effects": list(effects),
                                "params": {e: {"names": list(p), "values": list(p.values()),
                                               "std": [0.0] * len(p)} for e, p in effects.items()}}))
    return path


def _drive_torque(cfg: EpisodeConfig, speed: np.ndarray) -> np.ndarray:
    rt, _ = build_runtime(cfg)
    dofs = rt.scene.arm_dof_adr
    assert rt.drive is not None and np.all(rt.scene.model.dof_frictionloss[dofs] == 0)
    rt.scene.data.qvel[dofs] = speed
    rt.drive(rt.scene.data)
    return rt.scene.data.qfrc_applied[dofs].copy()


def test_a_diagnosed_sigmoid_is_the_cells_published_friction(tmp_path) -> None:
    """The cell twin's answer in sigmoid_friction's names, as a plant model, drives the arm with
    the very torque the concealed cell's own Gaz form does, bit for bit; a joint friction in
    the model replaces the config's friction, the sigmoid still acts beside it."""
    speed = np.array([-0.5, -0.08, -0.01, 0.0, 0.02, 0.1, 0.7])
    path = _model_file(tmp_path, {"sigmoid_friction": gaz_sigmoid_params(2.0)})
    truth = _drive_torque(EpisodeConfig(holes=1, arm_friction=2.0, arm_friction_form="gaz"), speed)
    fitted = _drive_torque(EpisodeConfig(holes=1, arm_friction=0.0, plant_model=str(path)), speed)
    np.testing.assert_array_equal(fitted, truth)
    assert truth[3] == 0 and np.all(truth[speed > 0.05] < 0) and np.all(truth[speed < -0.05] > 0)
    both = _model_file(tmp_path, {"sigmoid_friction": gaz_sigmoid_params(2.0), "joint_friction": {
        **{f"Fc{j}": 0.1 * j for j in J}, **{f"Fv{j}": 0.0 for j in J}}})
    rt, _ = build_runtime(EpisodeConfig(holes=1, arm_friction=2.0, arm_friction_form="gaz",
                                        plant_model=str(both)))
    dofs = rt.scene.arm_dof_adr
    np.testing.assert_allclose(rt.scene.model.dof_frictionloss[dofs], [0.1 * j for j in J])
    assert rt.drive is not None and len(rt.drive.law.sigmoids) == 1  # the config's gaz: replaced


def _push_joint7(cfg: EpisodeConfig, torque: float, seconds: float = 0.2) -> float:
    """Joint 7's travel [rad] under a constant torque, gravity and the motors off, from rest."""
    rt, _ = build_runtime(cfg)
    m, d = rt.scene.model, rt.scene.data
    m.opt.gravity[:] = 0.0
    d.ctrl[:] = 0.0
    j7 = rt.scene.arm_dof_adr[6]
    q0 = d.qpos[rt.scene.arm_qpos_adr[6]]
    for _ in range(round(seconds / m.opt.timestep)):
        if rt.drive is not None:
            rt.drive(d)
        d.qfrc_applied[j7] = torque
        mujoco.mj_step(m, d)
    return float(d.qpos[rt.scene.arm_qpos_adr[6]] - q0)


def test_a_stribeck_fall_and_rotor_inertia_act_on_the_cells_arm(tmp_path) -> None:
    """The fall is the joints' dry friction above its Coulomb level, as MuJoCo's frictionloss
    at each substep's speed: a joint at rest holds up to Fs = Fc + dFs, and slides at Fc."""
    fall = np.array([0.2, 0.5, 0.3, 0.8, 0.1, 0.4, 0.6])
    vs = np.array([0.02, 0.05, 0.1, 0.03, 0.2, 0.04, 0.08])
    ia = np.array([0.0, 0.05, 0.0, -0.04, 0.0, 0.0, 0.02])
    path = _model_file(tmp_path, {
        "stribeck_friction": {**{f"dFs{j}": fall[j - 1] for j in J}, **{f"vs{j}": vs[j - 1] for j in J}},
        "armature": {f"Ia{j}": ia[j - 1] for j in J}})
    cfg = EpisodeConfig(holes=1, plant_model=str(path))  # the nominal 0.3x Coulomb level beside
    rt, _ = build_runtime(cfg)
    m, d, dofs = rt.scene.model, rt.scene.data, rt.scene.arm_dof_adr
    np.testing.assert_allclose(m.dof_armature[dofs], 0.1 + ia, rtol=0, atol=1e-15)
    drive = rt.drive
    assert drive is not None and drive.torque(vs).tolist() == [0.0] * 7  # no torque: a level
    coulomb = 0.3 * np.array(PANDA_COULOMB_FRICTION)
    np.testing.assert_allclose(drive.base_loss, coulomb)
    np.testing.assert_allclose(drive.dry_level(np.zeros(7)), coulomb + fall)  # Fs at rest
    np.testing.assert_allclose(drive.dry_level(-vs), coulomb + fall / np.e)
    np.testing.assert_allclose(drive.dry_level(8 * vs), coulomb, rtol=1e-15)
    d.qvel[dofs] = 8 * vs
    drive(d)
    np.testing.assert_allclose(m.dof_frictionloss[dofs], coulomb, rtol=1e-15)
    # a push between the Coulomb and the static level: held with the fall, slides without it
    push = coulomb[6] + 0.5 * fall[6]
    assert abs(_push_joint7(cfg, push)) < 1e-4
    assert abs(_push_joint7(EpisodeConfig(holes=1), push)) > 0.05
    # the arm held by its controller, joints thrown at 0.3 rad/s: back and at rest
    held = d.qpos[rt.scene.arm_qpos_adr].copy()
    d.qvel[dofs] = 0.3
    for _ in range(300):
        rt.step()
    assert np.all(np.isfinite(d.qpos)) and np.abs(d.qvel[dofs]).max() < 0.02
    assert np.abs(d.qpos[rt.scene.arm_qpos_adr] - held).max() < 0.01


def test_what_the_drive_cannot_take_is_reported_and_mjcf_says_what_it_cannot_hold(tmp_path) -> None:
    params = gaz_sigmoid_params(1.0)
    params.update(phi1_2=-0.3, phi2_3=500.0)
    path = _model_file(tmp_path, {"sigmoid_friction": params,
                                  "armature": {f"Ia{j}": 0.01 for j in J}})
    rt, _ = build_runtime(EpisodeConfig(holes=1, plant_model=str(path)))
    notes = " | ".join(rt.scene.config.arm_plant.not_applied)
    assert "phi1_2 = -0.3 N m < 0: applied as 0" in notes and "phi2_3 = 500 s/rad" in notes
    assert rt.drive is not None and rt.drive.law.sigmoids[0][1][2] == 100.0
    out = export_arm_mjcf(read_model_file(path), tmp_path / "arm.xml")
    assert out.round_trip_max == 0.0 and out.applied == ("armature",)
    assert any(n.startswith("sigmoid_friction: ") and "drive torque" in n for n in out.not_expressed)
    with pytest.raises(ConfigError, match="too steep for the cell's 0.25 ms step"):
        DriveFriction.of_arm(rt.scene.model, "arm/", DriveFrictionLaw(sigmoids=(
            ((30.0,) * 7, (100.0,) * 7, (0.0,) * 7),)), 2.5e-4)
