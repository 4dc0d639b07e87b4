"""Physics of the 6-UPS Stewart platform model: closed loops, tracking, attach, robustness."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim.physics import PhysicsConfig, wake_tree_of
from serpar.sim.stewart import (
    N_LEGS,
    StewartConfig,
    build_stewart_spec,
    home_strokes,
    load_joint_table,
    loop_site_ids,
    loop_violation,
    spherical_angles_deg,
    stroke_for_pose,
)

CFG = StewartConfig()
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def _model() -> mujoco.MjModel:
    spec = build_stewart_spec()
    PhysicsConfig().apply(spec)
    return spec.compile()


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return _model()


def _pose(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    return data.sensor("platform_pos").data.copy(), data.sensor("platform_quat").data.copy()


def _settle(model: mujoco.MjModel, data: mujoco.MjData, ctrl: np.ndarray, seconds: float) -> float:
    """Hold ctrl for `seconds`; return the largest loop violation seen."""
    ids = loop_site_ids(model)
    data.ctrl[:] = ctrl
    worst = 0.0
    for _ in range(round(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
        worst = max(worst, loop_violation(model, data, site_ids=ids))
    return worst


def _quat_angle(q1: np.ndarray, q2: np.ndarray) -> float:
    return float(2 * np.arccos(min(1.0, abs(float(q1 @ q2)))))


def _jacobian(p: np.ndarray, b: np.ndarray, pos: np.ndarray, rot: np.ndarray) -> np.ndarray:
    rp = p @ rot.T
    n = pos + rp - b
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.hstack([n, np.cross(rp, n)])


def test_joint_table_matches_seed_table2() -> None:
    p, b = load_joint_table(swap_legs12=False)
    assert p.shape == b.shape == (N_LEGS, 3)
    np.testing.assert_allclose(p[0], [-0.0791608, -0.1381348, 0.0])
    np.testing.assert_allclose(b[2], [0.1447667, -0.0268462, 0.0])
    pc, bc = load_joint_table()  # the correction only exchanges P and B of legs 1 and 2
    np.testing.assert_array_equal(pc[:2, :2], b[:2, :2])
    np.testing.assert_array_equal(bc[2:], b[2:])
    for pp, bb in ((p, b), (pc, bc)):  # every leg has the same horizontal offset
        offsets = np.linalg.norm((pp - bb)[:, :2], axis=1)
        np.testing.assert_allclose(offsets, offsets[0], rtol=1e-5)


def test_printed_table_is_architecture_singular_corrected_is_not() -> None:
    """Table 2 as printed: the six leg lines are dependent at every pose; swapped: well posed."""
    rng = np.random.default_rng(3)
    printed, fixed = load_joint_table(swap_legs12=False), load_joint_table()
    for _ in range(20):
        pos = np.r_[rng.uniform(-0.03, 0.03, 2), rng.uniform(0.24, 0.29)]
        quat = np.r_[1.0, rng.uniform(-0.04, 0.04, 3)]
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, quat / np.linalg.norm(quat))
        for (p, b), bad in ((printed, True), (fixed, False)):
            sv = np.linalg.svd(_jacobian(p, b, pos, rot.reshape(3, 3)), compute_uv=False)
            assert (sv[-1] / sv[0] < 1e-7) == bad, sv
    with pytest.raises(ConfigError, match="swap_legs12"):
        StewartConfig(swap_legs12=False)


def test_stroke_covers_seed_z_range() -> None:
    """L_min = 246.8 mm: the 50.8 mm stroke spans the seed's Fig. 6 Z range 240-290 mm."""
    for z in (0.240, 0.290):
        s = stroke_for_pose(np.array([0, 0, z]), IDENTITY, CFG)
        assert np.all((s >= 0) & (s <= CFG.stroke)), (z, s)
    s_home = home_strokes(CFG)
    assert np.all(np.abs(s_home - CFG.stroke / 2) < 1e-3)  # home is about mid-stroke


def test_qpos0_closes_loops(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert loop_violation(model, data) < 1e-9
    pos, quat = _pose(model, data)
    np.testing.assert_allclose(pos, [0, 0, CFG.home_z], atol=1e-12)
    np.testing.assert_allclose(quat, IDENTITY, atol=1e-12)
    strokes = np.array([data.sensor(f"stroke{i}").data[0] for i in range(1, N_LEGS + 1)])
    np.testing.assert_allclose(strokes, home_strokes(CFG), atol=1e-12)
    np.testing.assert_allclose(spherical_angles_deg(model, data), 0, atol=1e-6)
    # Hinge stops are +-20 deg in radians (MjSpec defaults to degrees: a past bug).
    np.testing.assert_allclose(model.joint("u3_b").range, np.radians([-20, 20]))
    np.testing.assert_allclose(model.joint("leg3").range, [0, CFG.stroke])


def test_closed_loops_hold_under_gravity(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    worst = _settle(model, data, home_strokes(CFG), 0.5)
    pos, quat = _pose(model, data)
    assert worst <= 1e-6, f"loop violation {worst * 1e6:.4f} um"
    assert np.linalg.norm(pos - CFG.home_pos) <= 1e-5, f"pose error {(pos - CFG.home_pos) * 1e6} um"
    assert _quat_angle(quat, IDENTITY) < 1e-5
    # Gravity really loads the legs: their net axial force carries the weight (legs tilt ~13 deg).
    # The still platform has fallen asleep, and a sleeping tree reports no actuator force.
    wake_tree_of(data, model.body_dofadr[model.body("platform").id])
    mujoco.mj_forward(model, data)
    weight = -model.opt.gravity[2] * float(np.sum(model.body_mass))
    assert 0.5 * weight < float(np.sum(data.actuator_force)) < 1.5 * weight


def test_full_stroke_motion_keeps_loops_closed(model: mujoco.MjModel) -> None:
    """All legs ramp 2 -> 48.8 mm (a pure Z move) along a minimum-jerk profile in 1.5 s."""
    data = mujoco.MjData(model)
    ids = loop_site_ids(model)
    s0, s1, ramp = 0.002, CFG.stroke - 0.002, 1.5
    _settle(model, data, np.full(N_LEGS, s0), 0.3)
    t0, worst, z_min, z_max = data.time, 0.0, np.inf, -np.inf
    while data.time - t0 < ramp + 0.3:
        tau = min(1.0, (data.time - t0) / ramp)
        data.ctrl[:] = s0 + (s1 - s0) * (10 * tau**3 - 15 * tau**4 + 6 * tau**5)
        mujoco.mj_step(model, data)
        worst = max(worst, loop_violation(model, data, site_ids=ids))
        z = data.sensor("platform_pos").data[2]
        z_min, z_max = min(z_min, z), max(z_max, z)
    assert worst <= 1e-6, f"max loop violation {worst * 1e6:.4f} um during the motion"
    # Equal strokes give a pure Z pose: invert s = sqrt(h^2 + z^2) - l_min with h from the table.
    p, b = load_joint_table()
    h = np.linalg.norm((p - b)[0, :2])
    z_goal = np.sqrt((CFG.l_min + s1) ** 2 - h**2)
    pos, quat = _pose(model, data)
    assert abs(pos[2] - z_goal) <= 2e-5, f"final Z error {(pos[2] - z_goal) * 1e6:.2f} um"
    assert np.linalg.norm(pos[:2]) <= 2e-5 and _quat_angle(quat, IDENTITY) < 1e-4
    assert z_max - z_min > 0.045  # the platform really travelled ~47 mm


def test_lateral_pose_is_reached(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    goal_pos = np.array([0.020, 0.0, CFG.home_z])
    half = np.radians(3.0) / 2  # 3 deg about z
    goal_quat = np.array([np.cos(half), 0.0, 0.0, np.sin(half)])
    worst = _settle(model, data, stroke_for_pose(goal_pos, goal_quat, CFG), 1.0)
    pos, quat = _pose(model, data)
    assert np.linalg.norm(pos - goal_pos) <= 2e-5, f"pose error {(pos - goal_pos) * 1e6} um"
    assert _quat_angle(quat, goal_quat) <= np.radians(0.01)
    assert worst <= 1e-6
    assert np.all(spherical_angles_deg(model, data) < CFG.upper_hinge_limit_deg)


def test_attach_keeps_actuators_equalities_sensors() -> None:
    parent = mujoco.MjSpec()
    frame = parent.worldbody.add_frame(pos=[0.6, 0, 0])
    parent.attach(build_stewart_spec(), prefix="stewart/", frame=frame)
    PhysicsConfig().apply(parent)
    model = parent.compile()
    assert (model.nu, model.neq, model.nsensor) == (N_LEGS, N_LEGS, N_LEGS + 2)
    np.testing.assert_allclose(model.joint("stewart/u1_a").range, np.radians([-20, 20]))
    for i in range(1, N_LEGS + 1):
        assert model.actuator(f"stewart/leg{i}").trntype == mujoco.mjtTrn.mjTRN_JOINT
        assert model.equality(f"stewart/loop{i}").type == mujoco.mjtEq.mjEQ_CONNECT
        assert model.sensor(f"stewart/stroke{i}").type == mujoco.mjtSensor.mjSENS_JOINTPOS
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert loop_violation(model, data, prefix="stewart/") < 1e-9
    home_in_parent = [0.6, 0, CFG.home_z]
    np.testing.assert_allclose(data.sensor("stewart/platform_pos").data, home_in_parent, atol=1e-12)
    data.ctrl[:] = home_strokes(CFG)
    for _ in range(5000):
        mujoco.mj_step(model, data)
    assert loop_violation(model, data, prefix="stewart/") <= 1e-6
    np.testing.assert_allclose(data.sensor("stewart/platform_pos").data, home_in_parent, atol=1e-5)


@pytest.mark.parametrize("kwargs", [{"stroke": -1}, {"l_min": 0}, {"home_z": 0.5},
                                    {"lower_hinge_limit_deg": 0}, {"leg_kv": 1.0}])
def test_config_validation(kwargs: dict[str, float]) -> None:
    with pytest.raises(ConfigError):
        StewartConfig(**kwargs)


def test_servo_is_finite_bandwidth_and_damped() -> None:
    assert 20 <= CFG.servo_natural_hz <= 60
    assert 0.7 <= CFG.servo_damping_ratio <= 1.5


def test_random_commands_raise_no_warning(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    ctrl = home_strokes(CFG)
    for k in range(round(1.0 / model.opt.timestep)):
        if k % 500 == 0:  # a new random target every 50 ms: steps and saturation included
            ctrl = rng.uniform(0, CFG.stroke, N_LEGS)
        data.ctrl[:] = ctrl
        mujoco.mj_step(model, data)
    assert all(w.number == 0 for w in data.warning), [w.number for w in data.warning]
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
