"""Physics and numbers of the Panda-like arm asset (assets/arm/panda.xml, sim/arm.py)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim import arm
from serpar.sim.physics import PhysicsConfig

# Gaz et al., RA-L 2019 (as reproduced in MuJoCo Menagerie franka_emika_panda) [kg].
PUBLISHED_LINK_MASS = {
    "link0": 0.629769, "link1": 4.970684, "link2": 0.646926, "link3": 3.228604,
    "link4": 3.587895, "link5": 1.225946, "link6": 1.666555, "link7": 0.735522,
}
PUBLISHED_HAND_MASS = 0.73  # Franka Hand incl. fingers [kg]
CYL_RADIUS, CYL_HALF_LENGTH, CYL_MASS = 0.0025, 0.010, 0.002  # conductor body, Ø5.0 mm
KP = np.array([600.0, 600.0, 600.0, 600.0, 250.0, 150.0, 50.0])  # libfranka example gains
KD = np.array([50.0, 50.0, 50.0, 50.0, 30.0, 25.0, 15.0])


def _arm_model() -> mujoco.MjModel:
    spec = arm.build_arm_spec()
    PhysicsConfig().apply(spec)
    return spec.compile()


def _scene(with_cylinder: bool) -> mujoco.MjModel:
    """The arm attached with prefix "arm/" into an empty scene (the way sim/ builds scenes)."""
    spec = mujoco.MjSpec()
    spec.attach(arm.build_arm_spec(), prefix="arm/", frame=spec.worldbody.add_frame())
    PhysicsConfig().apply(spec)
    if with_cylinder:
        tcp = arm.mdh_forward_kinematics(arm.HOME_Q) @ np.array([0.0, 0.0, arm.TCP_OFFSET, 1.0])
        body = spec.worldbody.add_body(name="cyl", pos=tcp[:3])  # axis vertical, centred at tcp
        body.add_freejoint()
        body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[CYL_RADIUS, CYL_HALF_LENGTH, 0],
                      mass=CYL_MASS, friction=[1.0, 0.005, 0.0001], condim=4)
    return spec.compile()


def _adr(m: mujoco.MjModel, prefix: str = "") -> tuple[list[int], list[int], list[int]]:
    """qpos addresses, dof addresses, actuator ids of the 7 arm joints."""
    joints = [m.joint(prefix + n) for n in arm.JOINT_NAMES]
    acts = [m.actuator(prefix + n).id for n in arm.ACTUATOR_NAMES]
    return [j.qposadr[0] for j in joints], [j.dofadr[0] for j in joints], acts


def _tau_j(m: mujoco.MjModel, d: mujoco.MjData, prefix: str = "") -> np.ndarray:
    return np.array([d.sensor(prefix + n).data[arm.TORQUE_AXIS] for n in arm.TORQUE_SENSOR_NAMES])


def _random_q(rng: np.random.Generator, margin: float = 0.05) -> np.ndarray:
    lo, hi = np.array(arm.Q_MIN) + margin, np.array(arm.Q_MAX) - margin
    return rng.uniform(lo, hi)


def test_flange_site_matches_mdh_table() -> None:
    m = _arm_model()
    d = mujoco.MjData(m)
    qadr, _, _ = _adr(m)
    rng = np.random.default_rng(0)
    pos_err, rot_err = 0.0, 0.0
    for _ in range(20):
        q = _random_q(rng, margin=0.0)
        d.qpos[qadr] = q
        mujoco.mj_kinematics(m, d)
        fk = arm.mdh_forward_kinematics(q)
        pos_err = max(pos_err, float(np.linalg.norm(d.site("flange").xpos - fk[:3, 3])))
        dr = fk[:3, :3].T @ d.site("flange").xmat.reshape(3, 3)
        # rotation angle from the skew part: accurate near zero, unlike arccos of the trace
        axis = 0.5 * np.array([dr[2, 1] - dr[1, 2], dr[0, 2] - dr[2, 0], dr[1, 0] - dr[0, 1]])
        rot_err = max(rot_err, float(np.arcsin(min(1.0, np.linalg.norm(axis)))))
        # tcp: 0.1034 m along the flange z, same z axis (approach direction)
        tcp = fk @ np.array([0.0, 0.0, arm.TCP_OFFSET, 1.0])
        np.testing.assert_allclose(d.site("tcp").xpos, tcp[:3], atol=1e-9)
        np.testing.assert_allclose(d.site("tcp").xmat.reshape(3, 3)[:, 2], fk[:3, 2], atol=1e-9)
    print(f"FK max error: {pos_err:.2e} m, {rot_err:.2e} rad")
    assert pos_err < 1e-9 and rot_err < 1e-9


def test_home_pose_is_the_panda_ready_pose() -> None:
    fk = arm.mdh_forward_kinematics(arm.HOME_Q)
    # Franka's documented ready pose: flange at (0.307, 0, 0.590) m pointing down
    np.testing.assert_allclose(fk[:3, 3], [0.30689, 0.0, 0.59028], atol=1e-4)
    np.testing.assert_allclose(fk[:3, 2], [0.0, 0.0, -1.0], atol=1e-6)
    with pytest.raises(ConfigError):
        arm.mdh_forward_kinematics([0.0] * 6)


def test_masses_equal_published_values() -> None:
    m = _arm_model()
    for name, mass in PUBLISHED_LINK_MASS.items():
        assert m.body(name).mass[0] == pytest.approx(mass, abs=1e-9), name
    hand = (m.body("hand").mass[0] + m.body(arm.FINGER_CARRIER_BODY).mass[0]
            + sum(m.body(b).mass[0] for b in arm.FINGER_BODIES))
    assert hand == pytest.approx(PUBLISHED_HAND_MASS, abs=1e-9)
    moving = sum(PUBLISHED_LINK_MASS[f"link{i}"] for i in range(1, 8)) + PUBLISHED_HAND_MASS
    # subtree of link1 = everything that moves (link0 is the fixed base)
    assert m.body_subtreemass[m.body("link1").id] == pytest.approx(moving, abs=1e-9)
    print(f"moving mass {moving:.6f} kg, base {PUBLISHED_LINK_MASS['link0']} kg")


def test_limits_and_names_match_constants() -> None:
    m = _arm_model()
    for i, name in enumerate(arm.JOINT_NAMES):
        j = m.joint(name)
        assert j.limited[0] == 1
        np.testing.assert_array_equal(j.range, [arm.Q_MIN[i], arm.Q_MAX[i]])
        a = m.actuator(arm.ACTUATOR_NAMES[i])
        assert a.trnid[0] == j.id and a.gear[0] == 1.0
        lim = arm.TORQUE_LIMITS[i]
        assert a.ctrllimited[0] == 1 and a.forcelimited[0] == 1
        np.testing.assert_array_equal(a.ctrlrange, [-lim, lim])
        np.testing.assert_array_equal(a.forcerange, [-lim, lim])
        s = m.sensor(arm.TORQUE_SENSOR_NAMES[i])
        assert s.type[0] == mujoco.mjtSensor.mjSENS_TORQUE and s.dim[0] == 3
        assert m.site_bodyid[s.objid[0]] == m.body(f"link{i + 1}").id
    for jn in arm.FINGER_JOINT_NAMES:
        np.testing.assert_array_equal(m.joint(jn).range, [0.0, arm.FINGER_OPENING_MAX])
    np.testing.assert_array_equal(m.actuator(arm.GRIP_ACTUATOR).ctrlrange,
                                  [-arm.GRIP_FORCE_MAX, arm.GRIP_FORCE_MAX])


def test_gravity_compensation_holds_still_and_sensors_read_motor_torque() -> None:
    m = _arm_model()
    d = mujoco.MjData(m)
    qadr, vadr, acts = _adr(m)
    d.qpos[qadr] = arm.HOME_Q
    mujoco.mj_forward(m, d)
    tau = d.qfrc_bias[vadr].copy()  # at rest qfrc_bias is exactly the gravity torque
    assert np.all(np.abs(tau) < np.array(arm.TORQUE_LIMITS))
    d.ctrl[acts] = tau
    while d.time < 0.5:
        mujoco.mj_step(m, d)
    drift = np.abs(d.qpos[qadr] - arm.HOME_Q).max()
    print(f"drift after 0.5 s: {drift:.2e} rad; tau_J = {_tau_j(m, d).round(4)}")
    assert drift < 1e-4
    # Static: the parent transmits to each child subtree exactly the motor torque about the
    # joint axis (no acceleration, no velocity, so armature and damping add nothing). The
    # sensor is computed from the same RNE as qfrc_bias, so only round-off separates them.
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(_tau_j(m, d), d.actuator_force[acts],
                               atol=1e-6 * max(1.0, float(np.abs(tau).max())))


def test_torque_sensor_is_link_side_in_motion() -> None:
    """Moving: tau_J = tau_motor - armature*qacc - damping*qvel (rotor inertia and friction
    sit on the motor side of Franka's link-side torque sensors)."""
    m = _arm_model()
    d = mujoco.MjData(m)
    qadr, vadr, acts = _adr(m)
    rng = np.random.default_rng(1)
    for _ in range(5):
        d.qpos[qadr] = _random_q(rng, margin=0.1)
        d.qvel[vadr] = rng.uniform(-1.0, 1.0, 7)
        d.ctrl[acts] = rng.uniform(-1.0, 1.0, 7) * np.array(arm.TORQUE_LIMITS)
        mujoco.mj_forward(m, d)
        expected = (d.actuator_force[acts] - m.dof_armature[vadr] * d.qacc[vadr]
                    - m.dof_damping[vadr] * d.qvel[vadr])
        np.testing.assert_allclose(_tau_j(m, d), expected, atol=1e-8)


def test_gripper_holds_conductor_while_lifting() -> None:
    m = _scene(with_cylinder=True)
    d = mujoco.MjData(m)
    qadr, vadr, acts = _adr(m, "arm/")
    fingers = [m.joint("arm/" + n).qposadr[0] for n in arm.FINGER_JOINT_NAMES]
    grip = m.actuator("arm/" + arm.GRIP_ACTUATOR).id
    d.qpos[qadr] = arm.HOME_Q
    d.qpos[fingers] = CYL_RADIUS + 0.0005  # 0.5 mm gap each side
    mujoco.mj_forward(m, d)
    # joint step that lifts the tcp 30 mm straight up, orientation fixed
    jp, jr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    mujoco.mj_jacSite(m, d, jp, jr, m.site("arm/tcp").id)
    dq = np.linalg.pinv(np.vstack([jp, jr])[:, vadr]) @ np.array([0, 0, 0.03, 0, 0, 0])

    def cyl_in_tcp() -> np.ndarray:
        site = d.site("arm/tcp")
        return site.xmat.reshape(3, 3).T @ (d.body("cyl").xpos - site.xpos)

    z0, rel0 = d.body("cyl").xpos[2], None
    while d.time < 1.2:
        s = min(1.0, max(0.0, (d.time - 0.2) / 0.4))  # hold 0.2 s, smooth 0.4 s lift, hold
        qd = np.array(arm.HOME_Q) + s * s * (3 - 2 * s) * dq
        d.ctrl[acts] = d.qfrc_bias[vadr] + KP * (qd - d.qpos[qadr]) - KD * d.qvel[vadr]
        d.ctrl[grip] = 20.0
        mujoco.mj_step(m, d)
        if rel0 is None and d.time >= 0.2:
            rel0 = cyl_in_tcp()  # grasp settled: start measuring slip
    assert rel0 is not None
    slip = float(np.linalg.norm(cyl_in_tcp() - rel0))
    squeeze = np.zeros(6)
    normal = 0.0
    for i in range(d.ncon):
        mujoco.mj_contactForce(m, d, i, squeeze)
        normal += squeeze[0]
    lift = d.body("cyl").xpos[2] - z0
    print(f"slip {slip * 1e3:.4f} mm, lift {lift * 1e3:.2f} mm, pad normal force {normal:.2f} N")
    assert lift == pytest.approx(0.03, abs=1e-3)
    assert slip < 1e-4
    assert normal == pytest.approx(2 * 20.0, rel=1e-3)  # 20 N per pad (grip = squeeze per pad)
    assert all(w.number == 0 for w in d.warning)


def test_attached_model_has_actuators_sensors_and_finger_coupling() -> None:
    m = _scene(with_cylinder=False)
    for n in arm.ACTUATOR_NAMES:
        assert m.actuator("arm/" + n).trntype[0] == mujoco.mjtTrn.mjTRN_JOINT
    for n in arm.TORQUE_SENSOR_NAMES:
        assert m.sensor("arm/" + n).dim[0] == 3
    assert m.actuator("arm/" + arm.GRIP_ACTUATOR).trntype[0] == mujoco.mjtTrn.mjTRN_TENDON
    eq = m.equality("arm/" + arm.FINGER_EQUALITY)
    assert eq.type[0] == mujoco.mjtEq.mjEQ_JOINT
    assert {eq.obj1id[0], eq.obj2id[0]} == {m.joint("arm/" + n).id for n in arm.FINGER_JOINT_NAMES}
    for g in arm.PAD_GEOMS:  # pads collide with default (contype 1) world geoms
        assert m.geom("arm/" + g).conaffinity[0] & 1
    assert m.nu == 8 and m.nsensor == 7


def test_random_torques_raise_no_warning() -> None:
    m = _scene(with_cylinder=False)
    d = mujoco.MjData(m)
    qadr, vadr, acts = _adr(m, "arm/")
    grip = m.actuator("arm/" + arm.GRIP_ACTUATOR).id
    d.qpos[qadr] = arm.HOME_Q
    rng = np.random.default_rng(2)
    noise = 0.05 * np.array(arm.TORQUE_LIMITS)
    while d.time < 1.0:
        if round(d.time * 1e4) % 10 == 0:  # new noise at the 1 kHz control rate
            d.ctrl[acts] = d.qfrc_bias[vadr] + rng.uniform(-1, 1, 7) * noise
            d.ctrl[grip] = rng.uniform(-5.0, 20.0)
        mujoco.mj_step(m, d)
    assert [w.number for w in d.warning] == [0] * len(d.warning)
    assert np.all(np.isfinite(d.qpos)) and not math.isnan(d.time)
