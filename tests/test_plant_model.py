"""A diagnosis model file as the simulated arm's plant (EpisodeConfig.plant_model ->
SceneConfig.arm_plant -> the built scene), and `serpar diagnose --model` (effects held fixed)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import mujoco
import numpy as np
import pytest

from serpar.cli.entry import main
from serpar.errors import ConfigError
from serpar.kinematics.mdh import forward, panda_chain
from serpar.sim import names
from serpar.sim.arm import HOME_Q, JOINT_NAMES
from serpar.sim.config_io import load_yaml_config
from serpar.sim.model_file import read_model_file
from serpar.sim.plants.arm_changes import PAYLOAD_BODY, inertia_from_extent
from serpar.sim.plants.from_model_file import KNOWN_EFFECTS, arm_plant_from_file
from serpar.sim.scene import Scene, SceneConfig, build_scene
from serpar.tasks.episode_config import EpisodeConfig, scene_config

DATA = Path(__file__).resolve().parent / "data"
PAYLOAD = DATA / "payload_twin.model.json"
"""`serpar twin --effect payload --seed 1` (true mass 1.1087449 kg) diagnosed with --report."""
PANDA_1 = DATA / "panda1.model.json"
"""`serpar diagnose ../shared/realdata/panda_1 --report`: geometric, compliance, backlash."""
Q_TEST = np.array([0.3, -0.5, 0.4, -2.1, 0.6, 1.9, -0.4])


def _model_file(tmp_path: Path, effects: dict[str, dict[str, float]], name: str = "m") -> Path:
    blocks = {e: {"names": list(p), "values": list(p.values()), "std": [0.0] * len(p)}
              for e, p in effects.items()}
    path = tmp_path / f"{name}.model.json"
    path.write_text(json.dumps({"source": "test", "kind": "arm_dynamics",
                                "effects": [e for e in effects if e != "torque_tare"],
                                "params": blocks}))
    return path


def _scene(plant_file: Path | None = None) -> Scene:
    plant = arm_plant_from_file(plant_file) if plant_file else None
    return build_scene(SceneConfig(n_conductors=0, arm_plant=plant))


def _flange(scene: Scene, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    scene.data.qpos[scene.arm_qpos_adr] = q
    mujoco.mj_kinematics(scene.model, scene.data)
    site = scene.model.site(names.ARM + "flange").id
    return scene.data.site_xpos[site].copy(), scene.data.site_xmat[site].reshape(3, 3).copy()


def test_payload_model_adds_its_weight_at_the_flange() -> None:
    nominal, plant = _scene(), _scene(PAYLOAD)
    p = read_model_file(PAYLOAD).block("payload").as_dict()
    m = p["mass"]
    # both scenes reset to the ready pose at rest: qfrc_bias is the gravity torque
    tau0 = nominal.data.qfrc_bias[nominal.arm_dof_adr]
    tau1 = plant.data.qfrc_bias[plant.arm_dof_adr]
    pos, rot = _flange(plant, np.asarray(HOME_Q))
    com = pos + rot @ np.array([p["com_x"], p["com_y"], p["com_z"]])
    weight = m * plant.model.opt.gravity
    expected = []
    for j in JOINT_NAMES:  # torque that holds m at the CoM: -axis . ((com - anchor) x m g)
        jid = plant.model.joint(names.ARM + j).id
        lever = com - plant.data.xanchor[jid]
        expected.append(-plant.data.xaxis[jid] @ np.cross(lever, weight))
    np.testing.assert_allclose(tau1 - tau0, expected, rtol=0, atol=1e-9)
    assert abs(tau1[1] - tau0[1]) > 1.0  # joint 2 carries it: ~m g x 0.5 m, not a rounding
    body = plant.model.body(names.ARM + PAYLOAD_BODY)
    assert body.mass[0] == pytest.approx(m, abs=1e-12)
    link7 = nominal.model.body(names.ARM + "link7").id
    gained = plant.model.body_subtreemass[link7] - nominal.model.body_subtreemass[link7]
    assert gained == pytest.approx(m, abs=1e-12)


def test_payload_in_its_extent_is_the_same_body_as_its_inertia(tmp_path) -> None:
    """A model file may give the payload as diagnose fits it (extent Lxx..Lzz) or as an inertia
    tensor: the same body either way."""
    common = {"mass": 0.9, "com_x": 0.01, "com_y": -0.02, "com_z": 0.05}
    extent = {"Lxx": 0.03, "Lyx": 0.01, "Lyy": 0.02, "Lzx": -0.005, "Lzy": 0.004, "Lzz": 0.04}
    inertia = dict(zip(("Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz"),
                       inertia_from_extent(0.9, tuple(extent.values())), strict=True))
    a = arm_plant_from_file(_model_file(tmp_path, {"payload": {**common, **extent}}, "a"))
    b = arm_plant_from_file(_model_file(tmp_path, {"payload": {**common, **inertia}}, "b"))
    assert a.payload == b.payload and a.payload is not None
    with pytest.raises(ConfigError, match="Lzz missing"):
        del extent["Lzz"]
        arm_plant_from_file(_model_file(tmp_path, {"payload": {**common, **extent}}, "c"))


def test_friction_model_sets_frictionloss_and_replaces_arm_friction(tmp_path) -> None:
    fc = [0.3, 0.4, 0.2, 0.6, -0.01, 0.15, 0.3]
    fv = [0.05, 0.1, 0.02, 0.2, 0.0, 0.01, -0.3]
    path = _model_file(tmp_path, {
        "joint_friction": {**{f"Fc{j + 1}": v for j, v in enumerate(fc)},
                           **{f"Fv{j + 1}": v for j, v in enumerate(fv)}},
        "torque_tare": {f"tare{j}": 0.01 for j in range(1, 8)}})
    cfg = EpisodeConfig(plant_model=str(path))  # arm_friction stays at its default 0.3
    cell = scene_config(cfg)
    assert cell.arm_joint_friction == ()  # the diagnosed friction is the total
    scene = build_scene(dataclasses.replace(cell, n_conductors=0))
    dofs = scene.arm_dof_adr
    np.testing.assert_array_equal(scene.model.dof_frictionloss[dofs], np.maximum(fc, 0.0))
    np.testing.assert_allclose(scene.model.dof_damping[dofs], np.maximum(0.1 + np.array(fv), 0.0),
                               rtol=0, atol=1e-15)
    notes = " | ".join(cell.arm_plant.not_applied)
    assert "Fc5 = -0.01 N m < 0: applied as 0" in notes
    assert "Fv7" in notes and "torque_tare" in notes


def test_panda_1_model_applies_geometry_and_reports_the_rest() -> None:
    plant = arm_plant_from_file(PANDA_1)
    notes = " | ".join(plant.not_applied)
    for effect in ("joint_compliance", "backlash", "base.rx", "baseline"):
        assert effect in notes
    assert plant.mdh_errors[3][2] == pytest.approx(-0.022753228974758753)  # j4.theta
    assert plant.frictionloss == () and plant.payload is None


def test_geometric_errors_move_the_flange_exactly_as_the_mdh_chain(tmp_path) -> None:
    geo = read_model_file(PANDA_1).block("geometric").as_dict()
    geo = {k: v for k, v in geo.items() if not k.startswith("base.")}  # not applied: see above
    geo.update({"j3.beta": 2e-3, "j7.beta": -1.5e-3})  # the tilt of the next frame, too
    path = _model_file(tmp_path, {"geometric": geo})
    scene, nominal = _scene(path), _scene()
    chain = panda_chain()
    delta = np.array([geo.get(n, 0.0) for n in chain.names])
    for q in (Q_TEST, np.asarray(HOME_Q)):
        pose = forward(chain, chain.values(delta), q[None, :])[0]
        pos, rot = _flange(scene, q)
        np.testing.assert_allclose(pos, pose[:3, 3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(rot, pose[:3, :3], rtol=0, atol=1e-12)
        assert np.linalg.norm(pos - _flange(nominal, q)[0]) > 1e-3  # the errors do move it


def test_encoder_offsets_are_joint_references(tmp_path) -> None:
    off = {"offset2": 0.004, "offset3": -0.003, "offset4": 0.002, "offset5": -0.001,
           "offset6": 0.0035}
    dyn = _scene(_model_file(tmp_path, {"encoder_offset": off}, "dyn"))
    static = _scene(_model_file(tmp_path, {"encoder": {"o2": 0.004, "s3": 1e-3}}, "static"))
    nominal = _scene()
    shift = np.zeros(7)
    for k, v in off.items():
        shift[int(k[-1]) - 1] = v
    # measured = true + offset: the plant at reading q stands where the nominal arm is at q - offset
    np.testing.assert_allclose(_flange(dyn, Q_TEST)[0], _flange(nominal, Q_TEST - shift)[0],
                               rtol=0, atol=1e-12)
    # the static family's link = q + o
    o = np.array([0.0, 0.004, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(_flange(static, Q_TEST)[0], _flange(nominal, Q_TEST + o)[0],
                               rtol=0, atol=1e-12)
    assert any("s3" in n and "not expressible" in n for n in static.config.arm_plant.not_applied)


def test_link_inertia_scales_mass_and_inertia(tmp_path) -> None:
    scene = _scene(_model_file(tmp_path, {"link_inertia": {"link4": 0.2, "link3": -0.1}}))
    nominal = _scene()
    for link, s in (("link4", 0.2), ("link3", -0.1), ("link5", 0.0)):
        a, b = scene.model.body(names.ARM + link), nominal.model.body(names.ARM + link)
        assert a.mass[0] == pytest.approx((1 + s) * b.mass[0], rel=1e-12)
        np.testing.assert_allclose(a.inertia, (1 + s) * b.inertia, rtol=1e-9)
        np.testing.assert_allclose(a.ipos, b.ipos, atol=1e-12)


def test_latency_delays_the_arm_torque_and_reset_holds(tmp_path) -> None:
    scene = _scene(_model_file(tmp_path, {"latency": {"delay": 0.003}}))
    m, d = scene.model, scene.data
    q0 = d.qpos[scene.arm_qpos_adr].copy()
    for _ in range(50):  # the command history starts full of the holding torque
        mujoco.mj_step(m, d)
    assert np.abs(d.qpos[scene.arm_qpos_adr] - q0).max() < 1e-6
    act = scene.arm_actuators[1]
    before = d.actuator_force[act]
    d.ctrl[act] += 5.0
    steps = 0
    while d.actuator_force[act] == before:
        mujoco.mj_step(m, d)
        steps += 1
    assert 0.003 <= steps * m.opt.timestep <= 0.003 + 2 * m.opt.timestep


@pytest.mark.parametrize("content, needle", [
    (None, "not found"),
    ("{not json", "not valid JSON"),
    ({"source": "x", "kind": "k", "effects": []}, "missing key(s) params"),
    ({"source": "x", "kind": "k", "effects": ["gremlins"],
      "params": {"gremlins": {"names": ["g"], "values": [1.0], "std": [0.1]}}},
     "unknown effect(s) gremlins; valid: joint_friction"),
    ({"source": "x", "kind": "k", "effects": ["payload"], "params": {}},
     "payload have no block"),
    ({"source": "x", "kind": "k", "effects": ["latency"],
      "params": {"latency": {"names": ["lag"], "values": [0.001], "std": [0.0]}}},
     "unknown parameter(s) lag; valid: delay"),
    ({"source": "x", "kind": "k", "effects": ["latency"],
      "params": {"latency": {"names": ["delay"], "values": [float("nan")], "std": [0.0]}}},
     "must be finite"),
])
def test_bad_model_files_are_one_line_config_errors(tmp_path, content, needle) -> None:
    path = tmp_path / "bad.model.json"
    if content is not None:
        path.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(plant_model=str(path))
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_yaml_plant_model_key(tmp_path) -> None:
    cfg_file = tmp_path / "e.yaml"
    cfg_file.write_text(f"seed: 2\nplant_model: {PAYLOAD}\n")
    cfg = load_yaml_config(EpisodeConfig, cfg_file)
    assert scene_config(cfg).arm_plant.payload.mass == pytest.approx(1.108507507222977)
    bad = tmp_path / "b.yaml"
    bad.write_text("plant_model: /nonexistent/x.model.json\n")
    with pytest.raises(ConfigError, match="not found"):
        load_yaml_config(EpisodeConfig, bad)


def test_every_arm_twin_effect_has_a_plant_mapping_or_a_reason() -> None:
    """Every effect an arm or episode diagnosis can write: the arm twins' and the episode's
    insertion contact friction."""
    from serpar.diagnosis import insertion_friction as insertion
    from serpar.twins import arm_dynamics_twin as twin_arm_dynamics
    from serpar.twins import arm_static_twin as twin_arm_static

    # what a diagnosis can write: the library's effects (the twins' out-of-library effects
    # reach a model file only as an empirical term)
    # link_inertial: a candidate for arms whose file has CAD inertials; no twin draws it yet
    written = (set(twin_arm_static.EFFECTS) | set(twin_arm_dynamics.EFFECTS) | {insertion.NAME}
               | {"link_inertial"}) - set(twin_arm_dynamics.OUT_OF_LIBRARY)
    assert written == set(KNOWN_EFFECTS)


# -- serpar diagnose --model --------------------------------------------------------------------
def _diagnose(capsys, *args: str) -> tuple[int, dict]:
    capsys.readouterr()
    rc = main(["diagnose", *args, "--json"])
    out = capsys.readouterr().out
    return rc, (json.loads(out) if rc == 0 else {})


def test_diagnose_against_its_own_model_finds_nothing_left(tmp_path, capsys) -> None:
    rec = tmp_path / "twin"
    assert main(["twin", "--effect", "geometric", "--seed", "1", "--out", str(rec)]) == 0
    rc, first = _diagnose(capsys, str(rec), "--report", str(tmp_path / "a.html"))
    assert rc == 0 and first["top_effect"] == "geometric"
    assert first["plant"]["applied"] == ["link frames (MD-H errors)"]
    model_a = tmp_path / "a.model.json"
    rc, second = _diagnose(capsys, str(rec), "--model", str(model_a),
                           "--report", str(tmp_path / "b.html"))
    assert rc == 0 and second["verdict"] == "no missing physics found beyond noise"
    assert second["fixed_effects"] == ["geometric"]
    a = json.loads(model_a.read_text())
    b = json.loads((tmp_path / "b.model.json").read_text())
    assert b["effects"] == ["geometric"] and b["prior_model"] == str(model_a)
    assert b["params"]["geometric"]["values"] == a["params"]["geometric"]["values"]

    # M half right: what is left is found, as a correction, and the combined model is the first
    half = json.loads(model_a.read_text())
    half["params"]["geometric"]["values"] = [0.5 * v for v in half["params"]["geometric"]["values"]]
    model_h = tmp_path / "half.model.json"
    model_h.write_text(json.dumps(half))
    rc, third = _diagnose(capsys, str(rec), "--model", str(model_h),
                          "--report", str(tmp_path / "c.html"))
    assert rc == 0 and third["top_effect"] == "geometric"
    assert "correction" in third["findings"][0]["summary"]
    c = json.loads((tmp_path / "c.model.json").read_text())["params"]["geometric"]
    va, vc = np.array(a["params"]["geometric"]["values"]), np.array(c["values"])
    assert np.all(np.abs(vc - va) <= 3 * np.array(c["std"]))


def test_diagnose_against_a_model_of_another_domain_is_a_clear_error(tmp_path, capsys) -> None:
    rec = tmp_path / "twin"
    assert main(["twin", "--effect", "none", "--domain", "arm_static", "--seed", "3",
                 "--out", str(rec)]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(rec), "--model", str(PAYLOAD)]) == 2
    err = capsys.readouterr().err
    assert "payload" in err and "cannot take as fixed" in err and "geometric" in err
    assert err.count("\n") == 1


def test_serpar_run_warns_what_the_plant_cannot_take(tmp_path, capsys) -> None:
    import argparse

    from serpar.cli.cmd_run import episode_config

    cfg_file = tmp_path / "e.yaml"
    cfg_file.write_text(f"plant_model: {PANDA_1}\n")
    args = argparse.Namespace(config=str(cfg_file), holes=None, seed=None, episodes=1, workers=1,
                              ray=None, record=None)
    assert episode_config(args).plant_model == str(PANDA_1)
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"plant model {PANDA_1}: applied link frames (MD-H errors)"
    assert any(line.startswith("warning: joint_compliance: not applicable") for line in err)
    assert any(line.startswith("warning: backlash: not applicable") for line in err)
