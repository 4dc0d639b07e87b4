"""The concealed cell (twins/cell_twin.py, `serpar twin --domain cell`) and the physics it
conceals that the cell did not have before: the published Panda friction (a drive torque) and
a torque-sensor delay (MuJoCo sensor history)."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from serpar.cli.entry import main
from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import GAZ_FRICTION_PHI, PANDA_COULOMB_FRICTION, TORQUE_SENSOR_NAMES
from serpar.sim.plants.arm_changes import ArmPlantChanges
from serpar.sim.plants.drive_friction import DriveFrictionLaw, gaz_friction_torque, gaz_levels
from serpar.sim.scene import SceneConfig, build_scene
from serpar.tasks.episode import build_runtime
from serpar.tasks.episode_config import EpisodeConfig
from serpar.twins.cell_twin import EFFECTS, concealed_cell, draw_effects


def test_gaz_friction_is_the_published_model() -> None:
    """Gaz et al.'s model code: tau_f = phi1/(1+exp(-phi2 (dq+phi3))) - phi1/(1+exp(-phi2 phi3))."""
    phi1, phi2, phi3 = (np.asarray(p) for p in GAZ_FRICTION_PHI)
    assert np.all(gaz_friction_torque(np.zeros(7)) == 0)  # no torque at rest
    fast = gaz_friction_torque(np.full(7, 50.0), 2.0)
    slow = gaz_friction_torque(np.full(7, -50.0), 2.0)
    level, offset = gaz_levels(2.0)
    np.testing.assert_allclose(fast, offset + level, atol=1e-9)
    np.testing.assert_allclose(slow, offset - level, atol=1e-9)
    np.testing.assert_allclose(level, phi1)  # 2 x phi1 / 2
    # the offset is the sigmoid's shift: ~ -phi1 phi2 phi3 / 4 for small phi2 phi3
    np.testing.assert_allclose(offset, -2 * phi1 * phi2 * phi3 / 4, rtol=0.05)
    with pytest.raises(ConfigError, match="valid 0 < scale <= 5"):
        DriveFrictionLaw.gaz(0.0)


def test_gaz_form_is_a_drive_torque_not_a_joint_element() -> None:
    rt, _ = build_runtime(EpisodeConfig(holes=1, arm_friction=2.0, arm_friction_form="gaz"))
    m, d = rt.scene.model, rt.scene.data
    dofs = [m.joint(names.ARM + f"joint{j}").dofadr[0] for j in range(1, 8)]
    assert np.all(m.dof_frictionloss[dofs] == 0) and rt.drive is not None
    d.qvel[dofs] = 0.4
    rt.step()  # the drive sets qfrc_applied from the speed at each substep's start
    np.testing.assert_allclose(d.qfrc_applied[dofs], -gaz_friction_torque(d.qvel[dofs], 2.0),
                               rtol=0.2)
    assert np.all(d.qfrc_applied[dofs] < 0)  # it opposes the motion
    nominal, _ = build_runtime(EpisodeConfig(holes=1))
    assert nominal.drive is None and np.all(nominal.scene.model.dof_frictionloss[dofs] > 0)
    with pytest.raises(ConfigError, match="arm_friction_form 'stribeck'; valid: coulomb, gaz"):
        EpisodeConfig(arm_friction_form="stribeck")


def test_torque_sensor_delay_reads_the_torque_that_late() -> None:
    """A 1.25 ms sensor delay (between two 0.1 ms steps: linear) against the same arm without."""
    scenes = [build_scene(SceneConfig(n_conductors=0, arm_plant=ArmPlantChanges(
        torque_sensor_delay=lag))) for lag in (0.0, 0.00125)]
    adr = [scenes[0].model.sensor(names.ARM + n).adr[0] + 2 for n in TORQUE_SENSOR_NAMES]
    rng = np.random.default_rng(0)
    reads: list[list[np.ndarray]] = [[], []]
    for k in range(120):
        tau = rng.normal(0, 3.0, 7) if k % 10 == 0 else None
        for i, scene in enumerate(scenes):
            if tau is not None:
                scene.data.ctrl[scene.arm_actuators] = tau
            mujoco.mj_step(scene.model, scene.data)
            reads[i].append(scene.data.sensordata[adr].copy())
    plain, late = np.array(reads[0]), np.array(reads[1])
    want = 0.5 * (plain[60 - 12] + plain[60 - 13])  # 12.5 steps earlier
    np.testing.assert_allclose(late[60], want, atol=1e-9)
    assert np.abs(late[60] - plain[60]).max() > 1e-3  # it is not the undelayed reading


def test_mix_draws_two_to_four_and_names_are_diagnoses() -> None:
    counts = [len(draw_effects("mix", np.random.default_rng(s))) for s in range(40)]
    assert min(counts) == 2 and max(counts) == 4
    assert set(EFFECTS) == {"joint_friction", "sensor_timing", "latency", "payload",
                            "contact_friction", "stribeck_friction", "armature"}
    old = {e for s in range(20) for e in draw_effects("mix", np.random.default_rng(s), s)}
    new = {e for s in range(20, 60) for e in draw_effects("mix", np.random.default_rng(s), s)}
    assert "stribeck_friction" not in old and "armature" not in old and new == set(EFFECTS)
    with pytest.raises(ConfigError, match="valid: mix, none, joint_friction"):
        draw_effects("gremlins", np.random.default_rng(0))
    changes, answer, model = concealed_cell("mix", 0, 3)
    drawn = [e["effect"] for e in answer["effects"]]
    assert model is None or set(model["effects"]) <= {"sensor_timing", "latency", "payload"}
    assert ("joint_friction" in drawn) == (changes.get("arm_friction_form") == "gaz")


DOCUMENTED_CELLS = {
    ("mix", 0, 2): ({"arm_friction": 2.688225604416168, "arm_friction_form": "gaz",
                     "contact_friction": 0.42139969527430443},
                    {"sensor_timing": {"lag": 0.0010807922759642403},
                     "payload": {"mass": 0.1577884281983653, "com_x": 0.010508244107880507,
                                 "com_y": -0.003963487540505614, "com_z": 0.07098151512559495},
                     "contact_friction": {"d_mu": 0.22139969527430442}}),
    ("mix", 1, 12): ({}, {"sensor_timing": {"lag": 0.0007121785491682982},
                          "payload": {"mass": 0.12500828180375356, "com_x": -0.008306277807662936,
                                      "com_y": 0.011725399112160004,
                                      "com_z": 0.036860875879408936}}),
    ("mix", 2, 12): ({}, {"sensor_timing": {"lag": 0.0008171261390801266},
                          "latency": {"delay": 0.0005436396951632854}}),
    ("mix", 3, 12): ({"contact_friction": 0.44505679751881944},
                     {"latency": {"delay": 0.00096732193415125},
                      "payload": {"mass": 0.26076360194615883, "com_x": -0.01086370577105614,
                                  "com_y": 0.01243902742962313, "com_z": 0.07664608189748402},
                      "contact_friction": {"d_mu": 0.24505679751881942}}),
    ("payload", 7, 2): ({}, {"payload": {"mass": 0.272409463338376, "com_x": 0.017419130809167137,
                                         "com_y": -0.010578268897966826,
                                         "com_z": 0.03402211991681977}}),
}
"""The concealed cells docs/diagnosis.md and docs/sim2real.md measure: what each draws (its
config changes, and every effect's parameters but the friction's, which the scale fixes)."""


@pytest.mark.parametrize("cell", list(DOCUMENTED_CELLS))
def test_the_documented_cells_draw_what_they_always_drew(cell) -> None:
    changes, answer, _ = concealed_cell(*cell)
    want_changes, want_params = DOCUMENTED_CELLS[cell]
    assert changes == want_changes
    params = {e["effect"]: e["params"] for e in answer["effects"]}
    assert {k: v for k, v in params.items() if k != "joint_friction"} == want_params
    if "arm_friction" in changes:  # the published form at the drawn scale, in both names
        (friction,) = [e for e in answer["effects"] if e["effect"] == "joint_friction"]
        also = friction["also"]
        assert also["effect"] == "sigmoid_friction"
        scale = changes["arm_friction"]
        assert also["params"]["phi1_4"] == pytest.approx(scale * 1.2794)
        assert also["params"]["phi2_6"] == 17.133 and also["params"]["phi3_3"] == -0.04607
        # the level at speed joint_friction states is half the swing
        assert friction["params"]["Fc4"] == pytest.approx(also["params"]["phi1_4"] / 2)


def test_a_cell_with_a_stribeck_fall_and_heavier_rotors_runs_them_in_its_arm(tmp_path) -> None:
    """The drawn answer, in diagnose's names, is the plant the cell runs (its model file)."""
    seed = next(s for s in range(20, 200) if {"stribeck_friction", "armature"} <= set(
        draw_effects("mix", np.random.default_rng([s, 30]), s)))
    changes, answer, model = concealed_cell("mix", seed, 1)
    params = {e["effect"]: e["params"] for e in answer["effects"]}
    fall, rotor = params["stribeck_friction"], params["armature"]
    assert all(0.15 * c <= fall[f"dFs{j}"] <= 0.45 * c for j, c in enumerate(PANDA_COULOMB_FRICTION, 1))
    assert all(0.02 <= fall[f"vs{j}"] <= 0.08 for j in range(1, 8))
    assert rotor["Ia1"] == rotor["Ia2"] == 0 and all(0.015 <= rotor[f"Ia{j}"] <= 0.15 for j in range(3, 8))
    assert model is not None and {"stribeck_friction", "armature"} <= set(model["effects"])
    path = tmp_path / "answer.model.json"
    path.write_text(json.dumps(model))
    rt, _ = build_runtime(EpisodeConfig(holes=1, plant_model=str(path), **changes))
    dofs = rt.scene.arm_dof_adr
    np.testing.assert_allclose(rt.scene.model.dof_armature[dofs],
                               0.1 + np.array([rotor[f"Ia{j}"] for j in range(1, 8)]), atol=1e-15)
    assert rt.drive is not None and rt.drive.law.stribeck_excess == tuple(
        fall[f"dFs{j}"] for j in range(1, 8))


@pytest.mark.slow
def test_a_recorded_concealed_cell_keeps_its_truth_out_of_the_recording(tmp_path) -> None:
    out = tmp_path / "cell"
    assert main(["twin", "--domain", "cell", "--effect", "mix", "--seed", "0", "--holes", "1",
                 "--out", str(out), "--json"]) == 0
    answer = json.loads((out / "answer.json").read_text())
    drawn = {e["effect"]: e for e in answer["effects"]}
    assert set(drawn) == {"joint_friction", "sensor_timing", "payload", "contact_friction"}
    rec = out / "episode_0"
    meta_text = (rec / "meta.json").read_text()
    meta = json.loads(meta_text)
    assert meta["model"]["cell_log"]["seed"] == 0 and meta["model"]["cell_log"]["holes"] == 1
    for key in ("episode_config", "arm_friction", "contact_friction", "plant_model", "gaz",
                "answer", "hidden_errors"):
        assert key not in meta_text, key
    concealed = [answer["concealed_config"]["arm_friction"], drawn["contact_friction"]["mu"],
                 drawn["payload"]["params"]["mass"], drawn["sensor_timing"]["params"]["lag"]]
    for value in concealed:  # no concealed number in any form the log could hold
        for text in (repr(value), f"{value:.6g}", f"{value:.4g}"):
            assert text not in meta_text, text
    assert sorted(p.name for p in rec.iterdir()) == ["episode.rrd", "meta.json", "signals.parquet"]
    assert (out / "answer.model.json").is_file()  # the plant it ran: beside, not inside
