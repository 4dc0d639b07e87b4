"""The model back in the user's own file (issue 48, item 6): the full-precision MJCF writer on
any spec, the user's arm (iiwa14 MJCF, UR5e URDF, the Stäubli TX40's CAD URDF) written with the
established effects, read back exactly and after an edit, and the user's URDF with the
friction its <dynamics> holds."""

from __future__ import annotations

import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest
from arm_cal_support import static_position_recording

from serpar.cli.entry import main
from serpar.errors import ConfigError
from serpar.sim.arm_from_file import arm_from_file
from serpar.sim.mjcf_export import arm_spec, export_mjcf, read_mjcf, round_trip
from serpar.sim.mjcf_robot import PAYLOAD_NAME
from serpar.sim.mjcf_writer import mjcf_text, precise_tree
from serpar.sim.model_file import parse_model
from serpar.sim.plants.arm_changes import EXTENT, ArmPlantChanges, inertia_from_extent
from serpar.sim.robot_dynamics import dynamics_model, dynamics_spec
from serpar.sim.tilt import tilted_gravity
from serpar.sim.urdf_export import export_urdf

ASSETS = Path(__file__).resolve().parents[1] / "assets"
IIWA, UR5E = str(ASSETS / "iiwa14" / "iiwa14.xml"), str(ASSETS / "ur5e" / "ur5e.urdf")
TX40_DIR = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "staubli_tx40"
TX40 = str(TX40_DIR / "urdf" / "tx40_mdh_modified.urdf")
NO_TX40 = pytest.mark.skipif(not TX40_DIR.is_dir(),
                             reason="../shared/realdata/staubli_tx40 not present")
ARMS = [pytest.param(IIWA, id="iiwa14"), pytest.param(UR5E, id="ur5e"),
        pytest.param(TX40, id="tx40", marks=NO_TX40)]
PAYLOAD = {"mass": 1.2345678901234, "com_x": 0.0123456789, "com_y": -0.0234567891,
           "com_z": 0.0456789123, "Lxx": 0.0312345, "Lyx": 0.001, "Lyy": 0.0298765,
           "Lzx": 0.0, "Lzy": 0.0021, "Lzz": 0.0271}


def _block(names: list[str], values: np.ndarray | list[float]) -> dict[str, list]:
    return {"names": names, "values": [float(v) for v in values], "std": [1e-3] * len(names)}


def _model(n: int, seed: int = 0) -> dict:
    """joint_friction, armature, payload, link_inertia and base_tilt at values of no round
    decimal form; coupled_pair, latency and sigmoid_friction, which MJCF cannot express for a
    file's arm; a baseline block."""
    rng = np.random.default_rng(seed)
    j = range(1, n + 1)
    return {"source": "test", "kind": "arm_dynamics",
            "effects": ["joint_friction", "armature", "payload", "link_inertia", "coupled_pair",
                        "latency", "base_tilt", "sigmoid_friction"],
            "params": {
                "joint_friction": _block([f"Fc{i}" for i in j] + [f"Fv{i}" for i in j],
                                         rng.uniform(0.1, 2.0, 2 * n)),
                "armature": _block([f"Ia{i}" for i in j], rng.uniform(0.01, 0.3, n)),
                "payload": _block(list(PAYLOAD), list(PAYLOAD.values())),
                "link_inertia": _block([f"link{i}" for i in j], rng.normal(0.0, 0.05, n)),
                "coupled_pair": _block(["Iam6", "fvm6", "fsm6"], [0.01, 0.2, 0.3]),
                "latency": _block(["delay"], [0.0012]),
                "base_tilt": _block(["alpha", "beta"], [0.0123456789, -0.00456789123]),
                "sigmoid_friction": _block([f"phi{k}_{i}" for k in (1, 2, 3) for i in j],
                                           rng.uniform(0.01, 1.0, 3 * n)),
                "torque_tare": _block([f"tare{i}" for i in j], rng.normal(0.0, 0.1, n))},
            "evidence": {"joint_friction": "explains 91.2 % of the held-out residual"}}


def _nominal(robot: str) -> mujoco.MjModel:
    return arm_from_file(robot).make_spec().compile()


@pytest.mark.parametrize("robot", ARMS)
def test_the_arm_round_trips_exactly_with_its_effects_in_view(robot: str, tmp_path) -> None:
    arm = arm_from_file(robot)
    model = parse_model(_model(arm.n), "m")
    out = export_mjcf(model, tmp_path / "deep" / "arm.xml", robot)
    assert (out.round_trip_max, out.round_trip_field, out.kept) == (0.0, "", ())
    assert out.applied == ("joint_friction", "armature", "payload", "link_inertia", "base_tilt")
    assert [n.split(":")[0] for n in out.not_expressed] == ["coupled_pair", "latency",
                                                            "sigmoid_friction", "torque_tare"]
    here = os.getcwd()
    try:
        os.chdir("/")  # plain MuJoCo, another working directory
        m = mujoco.MjModel.from_xml_path(str(out.path))
    finally:
        os.chdir(here)
    nominal, p = _nominal(robot), model.block("joint_friction").as_dict()
    np.testing.assert_array_equal(m.opt.gravity, tilted_gravity(nominal.opt.gravity,
                                                                model.block("base_tilt").values)[0])
    for j, name in enumerate(arm.joint_names, 1):  # every value bit for bit
        d, d0 = m.joint(name).dofadr[0], nominal.joint(name).dofadr[0]
        assert m.dof_frictionloss[d] == p[f"Fc{j}"]
        assert m.dof_damping[d] == nominal.dof_damping[d0] + p[f"Fv{j}"]
        assert m.dof_armature[d] == nominal.dof_armature[d0] + model.block("armature").values[j - 1]
    scale = model.block("link_inertia").values
    for s, body in zip(scale, arm.link_bodies):
        assert m.body(body).mass[0] == pytest.approx(nominal.body(body).mass[0] * (1 + s), rel=1e-15)
    payload = m.body(PAYLOAD_NAME)
    assert payload.mass[0] == PAYLOAD["mass"] and m.body_parentid[payload.id] == m.body(
        arm.flange_body).id
    np.testing.assert_array_equal(payload.ipos, [PAYLOAD[k] for k in ("com_x", "com_y", "com_z")])
    full = inertia_from_extent(PAYLOAD["mass"], [PAYLOAD[k] for k in EXTENT])
    assert sorted(payload.inertia) == pytest.approx(sorted(np.linalg.eigvalsh(
        [[full[0], full[3], full[4]], [full[3], full[1], full[5]], [full[4], full[5], full[2]]])))
    text = out.path.read_text()
    head = text.split("-->")[0]
    assert text.count("serpar diagnose: joint_friction: Fc") == arm.n
    assert "explains 91.2 % of the held-out residual" in text and "armature: Ia1 = " in text
    assert "- coupled_pair: one motor turning two joints" in head and "- latency:" in head
    read = read_mjcf(out.path)
    assert read.notes == () and read.model.effects == model.effects
    assert dict(read.model.blocks) == dict(model.blocks)
    assert read.arm == str(Path(robot).resolve())


def test_what_mujoco_cannot_express_rides_in_the_model_text(tmp_path) -> None:
    out = export_mjcf(parse_model(_model(6), "m"), tmp_path / "ur.xml", UR5E)
    raw = read_mjcf(out.path).model
    assert raw.block("coupled_pair").values == (0.01, 0.2, 0.3)
    assert raw.block("latency").values == (0.0012,)


@pytest.mark.parametrize("robot", ARMS)
def test_the_writer_alone_round_trips_the_nominal_arm(robot: str, tmp_path) -> None:
    """No source text: to_xml's tree with each number replaced (6 digits alone move the UR5e's
    dof_invweight0 by 3.5e-3, the TX40's by 2.4e-5)."""
    spec = dynamics_spec(robot)[0]
    tree = precise_tree(spec, tmp_path)
    (tmp_path / "a.xml").write_text(mjcf_text(tree.root))
    assert round_trip(spec, tmp_path / "a.xml") == (0.0, "") and tree.kept == ()
    (tmp_path / "b.xml").write_text(spec.to_xml())
    assert round_trip(spec, tmp_path / "b.xml")[0] > 0 or robot == IIWA


ODD = """<mujoco model="odd">
  <compiler angle="degree" eulerseq="XYZ"/>
  <option timestep="0.00123456789" gravity="0.1234567891 -0.3 -9.80665"/>
  <default>
    <joint damping="0.3333333333" armature="0.0123456789" range="-170.123456 170.123456"/>
    <geom type="capsule" size="0.0412345678" rgba="0.123456789 0.2 0.3 1"/>
    <default class="big"><joint damping="1.23456789e-3" frictionloss="0.7777777777"/></default>
  </default>
  <worldbody>
    <body name="b0" euler="10.1234567 20.7654321 30.1111111" pos="0.1234567891 0 0.3">
      <inertial pos="0.01 0.02 0.0312345678" mass="2.123456789"
                fullinertia="0.0123456 0.02345678 0.0345678 0.001234 -0.0002345 0.0003456"/>
      <joint name="j0" axis="0.3 0.4 0.5123456"/>
      <geom fromto="0 0 0 0.1 0.2 0.3333333"/>
      <frame pos="0.1 0.2 0.3" euler="5.5 6.6 7.7">
        <geom type="box" size="0.1 0.2 0.3333333"/>
        <site name="s" pos="0.011111111 0 0" axisangle="1 2 3 45.123"/>
        <body pos="0.01 0.02 0.030303" xyaxes="1 0.1 0 0 1 0.2">
          <joint class="big" axis="1 1 0.1"/>
          <geom type="sphere" size="0.02"/>
        </body>
      </frame>
      <body name="b1" pos="0 0.3 0.1" zaxis="0.1 0.2 0.9">
        <joint class="big" axis="0 1 0" ref="12.3456789" springref="3.33333333"/>
        <geom type="sphere" size="0.0456789123" mass="0.987654321"/>
        <site name="tip" pos="0 0 0.11111111111"/>
        <camera name="c" pos="0.1 0.2 0.3" euler="10 20 30" fovy="44.4444444"/>
      </body>
    </body>
  </worldbody>
  <actuator>
    <position name="p" joint="j0" kp="123.456789" ctrlrange="-1.23456789 1.23456789"/>
    <motor name="m" gear="3.14159265358979" joint="j0"/>
  </actuator>
  <sensor><jointpos name="q" joint="j0" noise="0.000123456789"/></sensor>
</mujoco>"""


def test_the_writer_takes_what_to_xml_reexpresses(tmp_path) -> None:
    """Degrees, Euler/axis-angle/xyaxes/zaxis orientations, frames, fromto, fullinertia,
    unnamed elements, defaults, actuator shortcuts: all exact."""
    spec = mujoco.MjSpec.from_string(ODD)
    tree = precise_tree(spec, tmp_path)
    (tmp_path / "odd.xml").write_text(mjcf_text(tree.root))
    assert round_trip(spec, tmp_path / "odd.xml") == (0.0, "") and tree.kept == ()
    assert round_trip(arm_spec(ArmPlantChanges()), _written(arm_spec(ArmPlantChanges()),
                                                            tmp_path / "p.xml")) == (0.0, "")


def _written(spec: mujoco.MjSpec, path: Path) -> Path:
    path.write_text(mjcf_text(precise_tree(spec, path.parent).root))
    return path


@NO_TX40
def test_meshes_stay_referenced_from_the_written_file(tmp_path) -> None:
    """The TX40's URDF with its meshes where they are (the published file names ROS package
    paths, absent here, which serpar drops): the export references them from its own folder."""
    urdf = tmp_path / "tx40.urdf"
    urdf.write_text(Path(TX40).read_text().replace(
        "package://staubli_tx40_description/meshes/", f"{TX40_DIR / 'meshes'}/"))
    out = export_mjcf(parse_model(_model(6), "m"), tmp_path / "out" / "tx40.xml", str(urdf))
    assert out.round_trip_max == 0.0
    files = [el.get("file", "") for el in ET.parse(out.path).getroot().iter("mesh")]
    assert len(files) == 7 and all(f.startswith("../") for f in files)
    assert mujoco.MjModel.from_xml_path(str(out.path)).nmesh == 7


@pytest.mark.parametrize("robot", [pytest.param(UR5E, id="ur5e"),
                                   pytest.param(TX40, id="tx40", marks=NO_TX40)])
def test_the_urdf_holds_the_friction_mujoco_reads(robot: str, tmp_path) -> None:
    model = parse_model(_model(6), "m")
    xml = export_mjcf(model, tmp_path / "arm.xml", robot)
    out = export_urdf(model, robot, tmp_path / "arm.urdf")
    assert len(out.joints) == 6
    assert [n.split(":")[0] for n in out.not_held] == ["armature", "payload", "link_inertia",
                                                       "coupled_pair", "latency", "base_tilt",
                                                       "sigmoid_friction"]
    a, b = mujoco.MjModel.from_xml_path(str(xml.path)), dynamics_model(out.path).model
    for name in out.joints:  # what MuJoCo reads from <dynamics>: the MJCF's values exactly
        assert a.dof_frictionloss[a.joint(name).dofadr[0]] == b.dof_frictionloss[b.joint(name).dofadr[0]]
        assert a.dof_damping[a.joint(name).dofadr[0]] == b.dof_damping[b.joint(name).dofadr[0]]
    before, after = Path(robot).read_text(), out.path.read_text()
    assert after.startswith(before[:before.index("<robot")])  # declaration, leading comments
    old, new = ET.fromstring(before), ET.fromstring(after)
    assert [e.tag for e in old.iter() if e.tag != "dynamics"] == [
        e.tag for e in new.iter() if e.tag != "dynamics"]
    assert [e.attrib for e in old.iter("inertia")] == [e.attrib for e in new.iter("inertia")]
    assert "serpar diagnose: joint_friction: Fc1 = " in after


def test_urdf_needs_a_urdf_and_the_arm_the_model_was_fitted_on(tmp_path) -> None:
    model = parse_model(_model(7), "m")
    with pytest.raises(ConfigError, match="is an MJCF .*its export is --mjcf"):
        export_urdf(model, IIWA, tmp_path / "a.urdf")
    with pytest.raises(ConfigError, match="reach joint 7, the robot ur5e .* has 6 joints"):
        export_mjcf(model, tmp_path / "a.xml", UR5E)


def test_an_edited_export_of_the_users_arm_is_read_by_its_elements(tmp_path) -> None:
    model = parse_model(_model(6), "m")
    out = export_mjcf(model, tmp_path / "ur.xml", UR5E)
    root = ET.parse(out.path)
    joint = next(e for e in root.iter("joint") if e.get("name") == "elbow_joint")
    joint.set("armature", "0.5")
    payload = next(e for e in root.iter("body") if e.get("name") == PAYLOAD_NAME)
    payload.find("inertial").set("mass", "2.5")
    root.write(out.path)
    read = read_mjcf(out.path)
    nominal = _nominal(UR5E)
    assert read.model.block("armature").as_dict()["Ia3"] == 0.5 - nominal.dof_armature[2]
    assert read.model.block("payload").as_dict()["mass"] == 2.5
    assert read.model.block("payload").names == model.block("payload").names  # the extent
    assert [n.split(": ")[1].split(" ")[0] for n in read.notes] == ["armature", "payload"]
    assert read.model.block("coupled_pair") == model.block("coupled_pair")


def test_export_mjcf_robot_end_to_end(tmp_path, capsys) -> None:
    path = tmp_path / "m.model.json"
    path.write_text(json.dumps(_model(6)))
    xml, urdf = tmp_path / "ur.xml", tmp_path / "ur.urdf"
    assert main(["export-mjcf", str(path), "--robot", UR5E, "--out", str(xml), "--urdf",
                 str(urdf), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["round_trip_max_abs"] == 0 and out["robot"] == UR5E
    assert out["urdf"]["joints"][0] == "shoulder_pan_joint"
    again = tmp_path / "again.xml"  # an export read back is of its own arm
    assert main(["export-mjcf", str(xml), "--out", str(again), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["robot"] == str(Path(UR5E).resolve())
    assert main(["export-mjcf", str(path), "--out", str(tmp_path / "p.xml"), "--urdf",
                 str(tmp_path / "p.urdf")]) == 2
    assert "serpar's Panda has no URDF" in capsys.readouterr().err


def test_diagnose_robot_writes_the_users_arm_and_urdf(tmp_path, capsys) -> None:
    """serpar diagnose REC --robot FILE --mjcf --urdf end to end, on a static recording of the
    UR5e: the geometry it establishes has no MJCF form for a file's arm (its frames are not
    MD-H frames) and rides in the model text; the arm is written exactly all the same."""
    rec = static_position_recording(UR5E, tmp_path / "ur")
    xml, urdf = tmp_path / "ur.xml", tmp_path / "ur.urdf"
    assert main(["diagnose", str(rec), "--robot", UR5E, "--mjcf", str(xml), "--urdf", str(urdf),
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["established"] == ["geometric"]
    assert out["mjcf"]["round_trip_max_abs"] == 0 and out["mjcf"]["applied"] == []
    assert out["mjcf"]["not_expressed"][0].startswith("geometric: serpar's geometric parameters")
    assert out["urdf"]["joints"] == [] and read_mjcf(xml).model.effects == ("geometric",)
    assert main(["diagnose", str(rec), "--urdf", str(tmp_path / "p.urdf")]) == 2
    assert "serpar's Panda has no URDF" in capsys.readouterr().err
    assert main(["diagnose", str(rec), "--robot", IIWA, "--urdf", str(tmp_path / "i.urdf")]) == 2
    assert "is an MJCF (<mujoco>): its export is --mjcf" in capsys.readouterr().err


def _random_spec(rng: np.random.Generator, degree: bool) -> mujoco.MjSpec:
    """A chain of bodies with every orientation form, full inertias, fromto capsules, a frame
    holding a geom, hinge and ball joints, an actuator and a sensor, all at random values."""
    spec = mujoco.MjSpec()
    spec.compiler.degree = degree
    spec.option.timestep = rng.uniform(1e-4, 1e-2)
    parent, forms = spec.worldbody, mujoco.mjtOrientation
    for k in range(6):
        body = parent.add_body(name=f"b{k}" if k % 2 else "", pos=rng.normal(0, 0.3, 3))
        if k % 4 == 0:
            body.quat = rng.normal(size=4)
        else:
            body.alt.type = (forms.mjORIENTATION_EULER, forms.mjORIENTATION_AXISANGLE,
                             forms.mjORIENTATION_ZAXIS)[k % 4 - 1]
            body.alt.euler, body.alt.axisangle, body.alt.zaxis = (
                rng.normal(0, 1, 3), rng.normal(size=4), rng.normal(size=3))
        if k % 2:
            a = rng.normal(size=(3, 3))
            second = a @ a.T * 0.01
            i = np.trace(second) * np.eye(3) - second
            body.explicitinertial, body.mass, body.ipos = True, rng.uniform(0.1, 5), rng.normal(0, 0.1, 3)
            body.fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
        ball = k == 3
        joint = body.add_joint(type=mujoco.mjtJoint.mjJNT_BALL if ball else mujoco.mjtJoint.mjJNT_HINGE,
                               axis=rng.normal(size=3), pos=rng.normal(0, 0.05, 3), name=f"j{k}")
        joint.damping, joint.armature = [rng.uniform(0, 2), 0, 0], rng.uniform(0, 0.3)
        joint.frictionloss = rng.uniform(0, 1)
        if not ball:
            joint.range, joint.ref = sorted(rng.uniform(-3, 3, 2)), rng.uniform(-0.5, 0.5)
        geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[rng.uniform(0.01, 0.1), 0, 0])
        geom.fromto, geom.rgba = rng.normal(0, 0.2, 6), rng.uniform(0, 1, 4)
        body.add_site(pos=rng.normal(0, 0.1, 3), quat=rng.normal(size=4))
        if k == 2:
            frame = body.add_frame(pos=rng.normal(0, 0.1, 3), quat=rng.normal(size=4))
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=rng.uniform(0.01, 0.1, 3),
                          pos=rng.normal(0, 0.1, 3)).set_frame(frame)
        parent = body
    act = spec.add_actuator(target="j0", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.gear, act.ctrlrange = np.r_[rng.uniform(0.5, 100), np.zeros(5)], [-1.5, rng.uniform(1, 9)]
    spec.add_sensor(type=mujoco.mjtSensor.mjSENS_JOINTPOS, objtype=mujoco.mjtObj.mjOBJ_JOINT,
                    objname="j0").noise = rng.uniform(0, 0.01)
    return spec


def test_the_writer_is_exact_on_random_specs(tmp_path) -> None:
    rng = np.random.default_rng(0)
    for trial in range(12):
        spec = _random_spec(rng, bool(trial % 2))
        tree = precise_tree(spec, tmp_path)
        path = tmp_path / f"r{trial}.xml"
        path.write_text(mjcf_text(tree.root))
        assert (round_trip(spec, path), tree.kept) == ((0.0, ""), ()), trial
