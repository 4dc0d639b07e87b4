"""Robot files as published, for dynamics (serpar.sim.robot_dynamics, serpar.sim.robot_repair):
the file's masses and inertias exactly as written, each repair named, a file that cannot be a
dynamics model one line; the shipped iiwa14 and UR5e against their published dynamics."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np
import pytest

from serpar.assets import asset_path
from serpar.errors import ConfigError
from serpar.sim.robot_dynamics import BOUND, dynamics_model, dynamics_spec
from serpar.sim.robot_file import load_robot

TX40 = (Path(__file__).resolve().parents[2] / "shared" / "realdata" / "staubli_tx40" / "urdf"
        / "tx40_mdh_modified.urdf")
IIWA = str(asset_path("iiwa14", "iiwa14.xml"))
UR5E = str(asset_path("ur5e", "ur5e.urdf"))
PANDA_XML = str(asset_path("arm", "panda.xml"))


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), \
        math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def _compiled_tensor(model: mujoco.MjModel, body: int) -> np.ndarray:
    """The body's inertia tensor about its centre of mass, in the body's frame."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.body_iquat[body])
    rot = rot.reshape(3, 3)
    return rot @ np.diag(model.body_inertia[body]) @ rot.T


def _file_inertials(path: Path) -> dict[str, tuple[float, np.ndarray, np.ndarray]]:
    """Per URDF link: (mass, centre of mass, tensor in the link frame), read with ElementTree."""
    out = {}
    for link in ET.parse(path).getroot().iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        origin = inertial.find("origin")
        xyz = np.array(origin.get("xyz", "0 0 0").split(), float)
        rot = _rpy(*np.array(origin.get("rpy", "0 0 0").split(), float))
        i = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
        tensor = np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]],
                           [i["ixz"], i["iyz"], i["izz"]]])
        out[link.get("name")] = (float(inertial.find("mass").get("value")), xyz,
                                 rot @ tensor @ rot.T)
    return out


@pytest.mark.skipif(not TX40.is_file(), reason="needs ../shared/realdata/staubli_tx40")
def test_tx40_urdf_loads_with_its_masses_as_written() -> None:
    robot = dynamics_model(TX40)
    m = robot.model
    assert robot.joint_names == tuple(f"joint_{k}" for k in range(1, 7))
    assert mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, robot.flange_body) == "tool0"
    file = _file_inertials(TX40)
    for name in ("base_link", "link_1", "link_2", "link_3", "link_4", "link_5", "link_6"):
        b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, name)
        mass, com, tensor = file[name]
        assert m.body_mass[b] == mass  # exactly the file's number: nothing bounded
        assert np.abs(m.body_ipos[b] - com).max() < 1e-15
        if name != "link_6":
            assert np.abs(_compiled_tensor(m, b) - tensor).max() < 1e-15
    # link_6's inertia is all zero in the file (and its 0.2 kg sits on joint 6's axis)
    link6 = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "link_6")
    assert np.array_equal(m.body_inertia[link6], [BOUND] * 3)
    assert robot.repairs == (
        ("dropped 7 mesh geoms whose files are absent "
         "(package://staubli_tx40_description/meshes/base_link.stl and 6 more)"),
        ("body 'link_6' (turned by 'joint_6'): principal inertia (0, 0, 0) kg m², below what "
         "MuJoCo takes: each zero moment set to 1e-06 kg m², its 0.2 kg kept; the file gives "
         "'joint_6' no other inertia about its axis"))
    # the file's own joint dynamics: <dynamics damping="0.0" friction="0.0"/>, no armature
    assert not (robot.armature.any() or robot.damping.any() or robot.frictionloss.any())
    assert load_robot(TX40).n_joints == 6  # and the kinematics reader takes the file too


LINK_INERTIAL = ('<inertial><origin xyz="{c}"/><mass value="{m}"/><inertia ixx="{i}" '
                 'iyy="{i}" izz="{i}" ixy="0" ixz="0" iyz="0"/></inertial>')


def _link(name: str, m: object = 1.0, i: object = 0.01, c: str = "0.1 0 0", extra: str = "",
          inertial: bool = True) -> str:
    return (f'<link name="{name}">' + (LINK_INERTIAL.format(c=c, m=m, i=i) if inertial else "")
            + extra + "</link>")


def _joint(name: str, parent: str, child: str, axis: str = "0 0 1", kind: str = "revolute",
           extra: str = "") -> str:
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 0 0.1"/><axis xyz="{axis}"/>'
            f'<limit lower="-2" upper="2" effort="1" velocity="1"/>{extra}</joint>')


def _arm(l1: str = "", l2: str = "", j1: str = "", j2_kind: str = "revolute",
         tail: str = "") -> str:
    """base - j1 (z) - l1 - j2 (y) - l2 [- tail]; l1/l2 markup replaces the default link."""
    return ('<robot name="r"><link name="base"/>' + _joint("j1", "base", "l1", extra=j1)
            + (l1 or _link("l1")) + _joint("j2", "l1", "l2", "0 1 0", j2_kind)
            + (l2 or _link("l2")) + tail + "</robot>")


def _write(tmp_path: Path, text: str, name: str = "arm.urdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


REPAIRED = [
    (_arm(l1=_link("l1", extra=LINK_INERTIAL.format(c="0.1 0 0.0", m="1.0", i=".01"))),
     "link 'l1': 2 identical <inertial> elements, 1 dropped"),
    (_arm(j1='<axis xyz="0 0 1.0"/>'), "joint 'j1': 2 identical <axis> elements, 1 dropped"),
    (_arm(l1=_link("l1", extra='<collision><geometry><box size="1 1 1"/></geometry><geometry>'
                               '<sphere radius="1"/></geometry></collision>')),
     ("link 'l1': a <collision> with 2 different <geometry> elements dropped (serpar uses no "
      "geometry of a robot file)")),
    (_arm(l1=_link("l1", inertial=False)),
     ("body 'l1' (turned by 'j1'): mass 0 kg and principal inertia (0, 0, 0) kg m², below what "
      "MuJoCo takes: each zero moment set to 1e-06 kg m², mass set to 1e-06 kg")),
    (_arm(l1=_link("l1", m=0)),
     "body 'l1' (turned by 'j1'): mass 0 kg, below what MuJoCo takes: mass set to 1e-06 kg"),
]


@pytest.mark.parametrize("text, repair", REPAIRED)
def test_unambiguous_repairs_are_named(tmp_path, text: str, repair: str) -> None:
    """What MuJoCo's URDF reader refuses (a repeated element) or cannot compile (a moving body
    without mass), repaired where the repair is unambiguous; both readers take the file."""
    path = _write(tmp_path, text)
    with pytest.raises(ValueError, match="repeated element|mass and inertia"):
        mujoco.MjModel.from_xml_path(str(path))
    robot = dynamics_model(path)
    assert robot.repairs == (repair,) and robot.joint_names == ("j1", "j2")
    assert load_robot(path).n_joints == 2
    l2 = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_BODY, "l2")
    assert robot.model.body_mass[l2] == 1.0  # the untouched link keeps its value exactly
    spec, repairs = dynamics_spec(path)  # the same, editable: a twin adds to it, then compiles
    again = spec.compile()
    assert repairs == robot.repairs and again.njnt == 2
    assert np.array_equal(again.body_mass, robot.model.body_mass)
    assert np.array_equal(again.body_inertia, robot.model.body_inertia)
    assert robot.link_bodies == ("l1", "l2")


REFUSED = [
    (_arm(l1=_link("l1", extra=LINK_INERTIAL.format(c="0.1 0 0", m=2, i=0.01))),
     "link 'l1' has 2 different <inertial> elements; which one counts is ambiguous: keep one"),
    (_arm(j1='<axis xyz="0 1 0"/>'),
     "joint 'j1' has 2 different <axis> elements; which one counts is ambiguous: keep one"),
    (_arm(l2=_link("l2", inertial=False),
          tail=_joint("j3", "l2", "l3", "1 0 0") + _link("l3", inertial=False)),
     "joint 'j2' moves no mass: the file's inertials are missing; dynamics needs them"),
    (_arm(j2_kind="prismatic"), "a slide (prismatic) joint 'j2'; only hinge (revolute)"),
]


@pytest.mark.parametrize("text, words", REFUSED)
def test_ambiguous_or_massless_file_is_one_line(tmp_path, text: str, words: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(ConfigError, match=r"^--robot .*arm\.urdf: ") as err:
        dynamics_model(path)
    assert words in str(err.value) and "\n" not in str(err.value)


MESH_ARM = """<mujoco model="m"><asset><mesh name="shell" file="absent.obj"/></asset>
 <worldbody><body name="b0"><joint name="j0" axis="0 0 1"/>{inertial}
 <geom type="mesh" mesh="shell"/><body name="b1" pos="0 0 0.3"><joint name="j1" axis="1 0 0"/>
 <inertial pos="0 0.1 0" mass="1" diaginertia="0.01 0.01 0.01"/><site name="flange"/></body>
 </body></worldbody></mujoco>"""


def test_absent_mesh_is_dropped_unless_it_gives_the_inertia(tmp_path) -> None:
    given = _write(tmp_path, MESH_ARM.format(
        inertial='<inertial pos="0 0 0.1" mass="2" diaginertia="0.02 0.02 0.02"/>'), "given.xml")
    robot = dynamics_model(given)
    assert robot.repairs == ("dropped 1 mesh geom whose files are absent (absent.obj)",)
    assert list(robot.model.body_mass[1:]) == [2.0, 1.0]
    inferred = _write(tmp_path, MESH_ARM.format(inertial=""), "inferred.xml")
    with pytest.raises(ConfigError, match="body 'b0' takes its inertia from mesh 'shell', whose "
                       "file absent.obj is absent; give the mesh file or an <inertial>"):
        dynamics_model(inferred)


def test_joints_beyond_the_flange_are_locked_and_the_controller_goes() -> None:
    """The Panda's MJCF: its gripper's joints are locked, the fingers' masses kept (the arm
    carries them), its actuators, keyframes and couplings dropped, contacts off."""
    robot = dynamics_model(PANDA_XML)
    m = robot.model
    assert robot.n_joints == 7 and m.njnt == 7 and m.nu == 0 and m.nkey == 0 and m.neq == 0
    assert set(robot.locked) >= {"finger_left", "finger_right"}
    full = mujoco.MjModel.from_xml_path(PANDA_XML)
    link7 = mujoco.mj_name2id(full, mujoco.mjtObj.mjOBJ_BODY, "link7")
    assert m.body_subtreemass[robot.moved[-1][0]] == pytest.approx(full.body_subtreemass[link7],
                                                                   abs=1e-12)
    assert m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert robot.flange_pose[2, 3] == pytest.approx(0.107)  # the flange site in link7


def test_no_value_of_the_file_is_bounded_silently(tmp_path) -> None:
    """A real but small inertia stays as written (MuJoCo's boundinertia would raise it), and a
    frame without mass (UR5e's tool0) keeps none."""
    path = _write(tmp_path, _arm(j1='<dynamics damping="1.5" friction="0.3"/>',
                                 l2=_link("l2", m=0.002, i=2e-9)))
    robot = dynamics_model(path)
    l2 = mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_BODY, "l2")
    assert robot.repairs == () and robot.model.body_mass[l2] == 0.002
    assert np.array_equal(robot.model.body_inertia[l2], [2e-9] * 3)
    assert list(robot.damping) == [1.5, 0.0] and list(robot.frictionloss) == [0.3, 0.0]
    ur5e = dynamics_model(UR5E)
    assert ur5e.repairs == () and ur5e.model.body_mass[ur5e.flange_body] == 0.0


def _bias_and_mass(model: mujoco.MjModel, q) -> tuple[np.ndarray, np.ndarray]:
    data = mujoco.MjData(model)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    return data.qfrc_bias.copy(), full


# MuJoCo Menagerie's kuka_iiwa_14/iiwa14.xml (the revision with the link2/4/6 inertial quats,
# meshes removed), compiled with MuJoCo 4.0: gravity torques [N m] and the mass matrix's upper
# triangle [kg m²] at two poses (assets/iiwa14/README.md).
MENAGERIE_IIWA14 = [
    ([0.3, -0.8, 0.5, 1.2, -0.7, 0.9, 0.2],
     (0, 59.8478056050237, 8.39494334662646, -20.9365369404663, 0.920320067003995,
      0.979769389502991, 0),
     (3.14811019708484, 0.229792834786602, 1.25488667580656, 0.432298109176037,
      -0.0536746167231277, 0.0116208703716664, 0.000491464687426405, 3.6287593084569,
      0.66625029289994, -1.04271523790246, 0.036075673986582, 0.0883916106881833,
      -0.000616537924718091, 0.728125127053586, -0.0209944646331567, -0.0137607039212489,
      0.0290283643076406, 0.00078364981667274, 0.834894922826845, -0.0432955111090294,
      -0.0369773049800083, 0.000504633050071325, 0.0189431151158075, -2.68535506226485e-07,
      0.000621609968270674, 0.0179418479999999, -2.40355993847448e-17, 0.00100000000000001)),
    ([-1.1, 0.6, -0.4, -1.5, 1.3, -0.5, 1.0],
     (0, -50.4655720754929, -5.74814143141575, 20.4555941581677, -0.760940960474293,
      -0.730000595664751, 0),
     (2.34293909298461, 0.187069375566193, 1.2720386954931, 0.219523148931768,
      0.00664266964610478, 0.0638584336749293, -0.000192152114980925, 3.03869927996376,
      0.465982668786137, -0.824163393173014, 0.0365180699109423, 0.0569311315236452,
      -0.000762846142383414, 0.874750242042668, -0.00292528824803644, 0.0112963623871069,
      0.0585010963828215, 0.000190002247278051, 0.862045312042274, -0.033217465783193,
      -0.0162818277436421, 0.000461954402020143, 0.013746401149942, -3.79115666777376e-07,
      0.000877582561890353, 0.017941848, 1.01414993896431e-17, 0.00099999999999999)),
]


@pytest.mark.parametrize("q, gravity, upper", MENAGERIE_IIWA14)
def test_iiwa14_dynamics_are_menageries(q, gravity, upper) -> None:
    robot = dynamics_model(IIWA)
    assert robot.repairs == () and np.array_equal(robot.armature, np.zeros(7))
    assert np.array_equal(robot.damping, np.full(7, 0.5))  # Drake's URDF, Menagerie's source
    bias, full = _bias_and_mass(robot.model, q)
    assert np.abs(bias - gravity).max() < 1e-12 * np.abs(gravity).max()
    assert np.abs(full[np.triu_indices(7)] - upper).max() < 1e-12 * max(map(abs, upper))


# UR's published UR5e dynamics, each in its DH frame i (assets/ur5e/README.md)
UR_D = (0.1625, 0, 0, 0.1333, 0.0997, 0.0996)
UR_A = (0, -0.425, -0.3922, 0, 0, 0)
UR_ALPHA = (math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0)
UR_MASS = (3.761, 8.058, 2.846, 1.37, 1.3, 0.365)
UR_COM = ((0, -0.02561, 0.00193), (0.2125, 0, 0.11336), (0.15, 0, 0.0265),
          (0, -0.0018, 0.01634), (0, 0.0018, 0.01634), (0, 0, -0.001159))
UR_TENSOR = (  # ixx, ixy, ixz, iyy, iyz, izz
    (0.0070021, 7.3e-7, -1.053e-5, 0.00648091, 0.00049994, 0.00657286),
    (0.01505885, -5.4e-5, 5.63e-6, 0.33388086, -1.81e-6, 0.33247207),
    (0.00399632, -1.365e-5, 0.00137272, 0.07879254, -6.6e-6, 0.0784851),
    (0.00165491, -2.82e-6, -4.38e-6, 0.00135962, 0.00010157, 0.00126279),
    (0.00135617, -2.74e-6, 4.44e-6, 0.00127827, -5.048e-5, 0.00096614),
    (0.00018694, 6e-8, -1.7e-7, 0.00018908, -9.2e-7, 0.00025756))


def _ur_dh_dynamics(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gravity torques and mass matrix from the DH-frame numbers, written out independently
    of MuJoCo (Jacobians of each link's centre of mass in the DH chain)."""
    frames, t = [np.eye(4)], np.eye(4)
    for th, d, a, al in zip(q, UR_D, UR_A, UR_ALPHA):
        ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
        t = t @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                          [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])
        frames.append(t)
    tau, full = np.zeros(6), np.zeros((6, 6))
    for i in range(6):
        rot, origin = frames[i + 1][:3, :3], frames[i + 1][:3, 3]
        com = rot @ UR_COM[i] + origin
        xx, xy, xz, yy, yz, zz = UR_TENSOR[i]
        inertia = rot @ np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) @ rot.T
        jv, jw = np.zeros((3, 6)), np.zeros((3, 6))
        for k in range(i + 1):
            axis, at = frames[k][:3, 2], frames[k][:3, 3]
            jv[:, k], jw[:, k] = np.cross(axis, com - at), axis
        full += UR_MASS[i] * jv.T @ jv + jw.T @ inertia @ jw
        tau += UR_MASS[i] * 9.81 * jv[2]  # holding the link against g = (0, 0, -9.81)
    return tau, full


def test_ur5e_dynamics_are_urs_published_values() -> None:
    robot = dynamics_model(UR5E)
    assert robot.repairs == () and not robot.armature.any() and not robot.damping.any()
    for q in np.random.default_rng(1).uniform(-math.pi, math.pi, (5, 6)):
        bias, full = _bias_and_mass(robot.model, q)
        tau, ref = _ur_dh_dynamics(q)
        assert np.abs(bias - tau).max() < 1e-12 * np.abs(tau).max()
        assert np.abs(full - ref).max() < 1e-12 * np.abs(ref).max()
