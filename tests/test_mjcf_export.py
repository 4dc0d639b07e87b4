"""A diagnosis model as the arm's MJCF (sim/mjcf_export.py, `serpar export-mjcf`, `serpar
diagnose --mjcf`): exact round trip, plain MuJoCo loads it anywhere, serpar run and diagnose
take it back, and a file edited after export is read by its elements."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from serpar.cli.entry import main
from serpar.errors import ConfigError
from serpar.sim.arm import JOINT_NAMES
from serpar.sim.mjcf_export import (
    arm_spec,
    export_arm_mjcf,
    read_mjcf,
    read_mjcf_model,
    round_trip,
)
from serpar.sim.model_file import parse_model, read_model_file
from serpar.sim.plants.arm_changes import MDH_PARAMS, PAYLOAD_BODY
from serpar.sim.plants.from_model_file import arm_plant_changes
from serpar.tasks.episode_config import EpisodeConfig, scene_config

DATA = Path(__file__).resolve().parent / "data"
PANDA_1 = DATA / "panda1.model.json"


def _block(names: list[str], values: np.ndarray) -> dict[str, list]:
    return {"names": names, "values": [float(v) for v in values], "std": [1e-4] * len(names)}


def _every_effect(seed: int = 1) -> dict:
    """A model with every effect the arm's MJCF can carry, values of no round decimal form."""
    rng = np.random.default_rng(seed)
    j = range(1, 8)
    geo = [f"j{i}.{p}" for i in j for p in MDH_PARAMS]
    return {"source": "test", "kind": "arm_dynamics",
            "effects": ["joint_friction", "payload", "link_inertia", "encoder_offset",
                        "geometric", "latency", "sensor_timing", "armature"],
            "params": {
                "joint_friction": _block([f"Fc{i}" for i in j] + [f"Fv{i}" for i in j],
                                         rng.uniform(0.1, 0.6, 14)),
                "payload": _block(["mass", "com_x", "com_y", "com_z", "Ixx", "Iyy", "Izz",
                                   "Ixy", "Ixz", "Iyz"],
                                  [0.3141592653589793, 0.0012345678901, -0.002, 0.04321987654,
                                   3e-4 + 1e-9 / 3, 3e-4, 2e-4, 0.0, 0.0, 0.0]),
                "link_inertia": _block([f"link{i}" for i in j], rng.normal(0, 0.05, 7)),
                "encoder_offset": _block([f"offset{i}" for i in j], rng.normal(0, 1e-3, 7)),
                "geometric": _block(geo, rng.normal(0, 1e-3, len(geo))),
                "latency": _block(["delay"], [0.0012345678901]),
                "sensor_timing": _block(["lag"], [0.00087654321]),
                "armature": _block([f"Ia{i}" for i in j], rng.uniform(-0.05, 0.05, 7))}}


def test_every_effect_round_trips_exactly_and_loads_from_any_directory(tmp_path) -> None:
    model = parse_model(_every_effect(), "every")
    out = export_arm_mjcf(model, tmp_path / "deep" / "arm.xml")
    assert out.round_trip_max == 0.0 and out.round_trip_field == ""
    assert set(out.applied) == set(model.effects) and out.not_expressed == ()
    here = os.getcwd()
    try:
        os.chdir("/")  # plain MuJoCo, another working directory: the file stands alone
        m = mujoco.MjModel.from_xml_path(str(out.path))
    finally:
        os.chdir(here)
    fc = model.block("joint_friction").values[:7]
    np.testing.assert_array_equal(m.dof_frictionloss[:7], fc)  # bit for bit, not 6 digits
    assert m.body(PAYLOAD_BODY).mass[0] == 0.3141592653589793
    assert m.actuator_delay[0] == 0.0012345678901 and m.opt.timestep == 1e-4
    assert m.actuator_history[0, 1] == 1  # read linearly: a continuous delay, not the step's
    assert m.sensor_delay[m.sensor("tau_J3").id] == 0.00087654321
    np.testing.assert_array_equal(m.dof_armature[:7], 0.1 + np.array(model.block("armature").values))
    text = out.path.read_text()
    assert text.count("serpar diagnose: joint_friction: Fc") == len(JOINT_NAMES)
    assert "latency: delay = 0.00123457 +- 0.0001" in text
    assert read_mjcf_model(out.path).effects == model.effects


def test_to_xml_alone_would_not_round_trip(tmp_path) -> None:
    """Why the writer replaces to_xml's numbers: MjSpec.to_xml's 6 digits move the arm (the
    nominal one's subtree masses by 1.4e-5 kg)."""
    spec = arm_spec(arm_plant_changes(parse_model(
        {"source": "x", "kind": "k", "effects": [], "params": {}}, "nominal")))
    path = tmp_path / "to_xml.xml"
    path.write_text(spec.to_xml())
    worst, where = round_trip(spec, path)
    assert worst > 1e-6 and where == "body_subtreemass"


def test_what_mujoco_cannot_express_is_listed_not_dropped(tmp_path) -> None:
    out = export_arm_mjcf(read_model_file(PANDA_1), tmp_path / "p1.xml")
    head = out.path.read_text().split("-->")[0]
    assert any(n.startswith("joint_compliance") for n in out.not_expressed)
    assert any(n.startswith("backlash") for n in out.not_expressed)
    assert "- joint_compliance:" in head and "- backlash:" in head
    assert out.applied == ("geometric",) and out.round_trip_max == 0.0


def _edit(path: Path, tag: str, name: str, attr: str, value: str) -> None:
    """Set one attribute of one named element in the file's text, as a user would."""
    text = path.read_text()
    start = text.index(f'<{tag} name="{name}"')
    end = text.index(">", start)
    end -= text[end - 1] == "/"  # a self-closed element keeps its "/>"
    element = re.sub(rf'\s{attr}="[^"]*"', "", text[start:end]).rstrip()
    path.write_text(text[:start] + element + f' {attr}="{value}"' + text[end:])


def test_an_edited_file_is_read_by_its_elements(tmp_path) -> None:
    """The elements win over the model text the file carries, each edit named in a note, the
    value std 0 (set by hand); what MJCF cannot express still comes from the model text."""
    model = parse_model(_every_effect(), "every")
    out = export_arm_mjcf(model, tmp_path / "arm.xml")
    _edit(out.path, "joint", "joint3", "damping", "0.75")
    _edit(out.path, "joint", "joint5", "frictionloss", "0.0625")
    read = read_mjcf(out.path)
    fitted, now = model.block("joint_friction").as_dict(), read.model.block("joint_friction")
    assert now.as_dict()["Fv3"] == 0.75 - 0.1  # the nominal 0.1 N m s/rad under it
    assert now.as_dict()["Fc5"] == 0.0625
    assert {n: v for n, v in now.as_dict().items() if n not in ("Fv3", "Fc5")} == {
        n: v for n, v in fitted.items() if n not in ("Fv3", "Fc5")}
    assert dict(zip(now.names, now.std))["Fv3"] == 0.0 and dict(zip(now.names, now.std))["Fv1"] == 1e-4
    assert len(read.notes) == 1 and "joint_friction edited after export" in read.notes[0]
    assert "Fv3" in read.notes[0] and "Fc5 " in read.notes[0]
    assert read.model.effects == model.effects
    assert read.model.block("geometric") == model.block("geometric")  # from the model text
    changes = arm_plant_changes(read.model)
    assert changes.damping[2] == pytest.approx(0.75, abs=1e-15) and changes.frictionloss[4] == 0.0625
    assert "edited in" in dict(read.model.evidence)["joint_friction"]


def test_an_edit_no_effect_is_written_into_is_named(tmp_path, capsys) -> None:
    out = export_arm_mjcf(parse_model(_every_effect(), "every"), tmp_path / "arm.xml")
    _edit(out.path, "geom", "link1_j2", "size", "0.07 0.065")
    _edit(out.path, "body", PAYLOAD_BODY, "pos", "0 0 0.2")
    model = read_mjcf_model(out.path)
    notes = capsys.readouterr().err
    assert "payload edited after export (com_z" in notes
    assert "geom_size differs by 0.01" in notes and "serpar's model does not hold it" in notes
    assert model.block("payload").as_dict()["com_z"] == pytest.approx(0.2 - 0.107 + 0.04321987654)
    read_mjcf_model(out.path)
    assert capsys.readouterr().err == ""  # once per version of the file
    plain = tmp_path / "plain.xml"
    plain.write_text("<mujoco><worldbody/></mujoco>")
    with pytest.raises(ConfigError, match="serpar reads back only the MJCF it exported"):
        read_mjcf_model(plain)


def test_episode_plant_model_takes_the_mjcf_as_the_json(tmp_path) -> None:
    raw = _every_effect()
    json_path = tmp_path / "m.model.json"
    json_path.write_text(json.dumps(raw))
    xml = export_arm_mjcf(read_model_file(json_path), tmp_path / "m.xml").path
    a = scene_config(EpisodeConfig(holes=1, plant_model=str(json_path))).arm_plant
    b = scene_config(EpisodeConfig(holes=1, plant_model=str(xml))).arm_plant
    assert a is not None and b is not None
    assert a.frictionloss == b.frictionloss and a.mdh_errors == b.mdh_errors
    assert a.payload == b.payload and a.actuation_delay == b.actuation_delay


def test_a_stewart_model_is_a_clear_error(tmp_path, capsys) -> None:
    path = tmp_path / "s.model.json"
    path.write_text(json.dumps({"source": "x", "kind": "stewart", "effects": ["leg_thermal_drift"],
                                "params": {"leg_thermal_drift": {"names": ["kappa"], "values": [1.0],
                                                            "std": [0.1]}}}))
    assert main(["export-mjcf", str(path), "--out", str(tmp_path / "s.xml")]) == 2
    err = capsys.readouterr().err
    assert "leg_thermal_drift" in err and "not the arm's" in err and err.count("\n") == 1


@pytest.mark.slow
def test_diagnose_writes_the_mjcf_and_rediagnosis_against_it_finds_nothing(tmp_path, capsys) -> None:
    rec = tmp_path / "twin"
    assert main(["twin", "--effect", "joint_friction", "--seed", "1", "--out", str(rec)]) == 0
    capsys.readouterr()
    xml = tmp_path / "arm.xml"
    assert main(["diagnose", str(rec), "--mjcf", str(xml), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["established"] == ["joint_friction"]
    assert first["mjcf"]["applied"] == ["joint_friction"] and first["mjcf"]["round_trip_max_abs"] == 0
    truth = json.loads((rec / "answer.json").read_text())
    assert "joint_friction" in json.dumps(truth)
    fitted = read_mjcf_model(xml).block("joint_friction")
    assert "whole fit: held-out RMS" in xml.read_text()  # the evidence rides in the comments
    assert main(["diagnose", str(rec), "--model", str(xml), "--json"]) == 0
    second = json.loads(capsys.readouterr().out)
    assert second["verdict"] == "no missing physics found beyond noise"
    assert second["fixed_effects"] == ["joint_friction"]
    assert second["model"]["params"]["joint_friction"]["values"] == list(fitted.values)
