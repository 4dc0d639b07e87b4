"""Arm controllers: the paper's figures with sensor noise on, the wrench estimate against
MuJoCo's contact force, limits and saturation reporting."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from serpar.checks.arm_checks import force_position_descent, path_accuracy, press
from serpar.cli.entry import main
from serpar.controllers.arm_controller import ArmController, ArmControllerConfig, ControlLaw
from serpar.controllers.arm_laws import ForceTarget, orientation_error
from serpar.controllers.arm_model import require_joint_target
from serpar.controllers.arm_sensors import ArmSensorConfig
from serpar.controllers.wrench import tcp_wrench
from serpar.errors import ConfigError, LimitError
from serpar.sim import names
from serpar.sim.arm import HOME_Q
from serpar.sim.arm_drive import quantise
from serpar.sim.scene import SceneConfig, build_scene


def test_path_to_paper_target_within_paper_bound_with_noise() -> None:
    r = path_accuracy(noise=True)
    assert max(r.max_deviation_mm) < 0.4  # seed 000 Fig. 3
    assert max(r.final_error_mm) < 0.01
    assert r.saturation == "no torque saturation"


def test_force_position_descent_within_paper_bound_with_noise() -> None:
    r = force_position_descent(noise=True)
    assert max(r.final_error_mm) < 0.2  # seed 000 Fig. 5


@pytest.fixture(scope="module")
def presses() -> dict[tuple[str, bool], object]:
    return {(law.value, noise): press(law, noise=noise)
            for law in (ControlLaw.IMPEDANCE, ControlLaw.FORCE_POSITION) for noise in (False, True)}


def test_wrench_estimate_matches_true_contact_force(presses) -> None:
    for law in ("impedance", "force_position"):
        assert presses[(law, False)].steady_estimate_error_n <= 0.3
        assert presses[(law, False)].steady_force_n > 4.0  # really in contact


def test_direct_force_position_regulates_5n_and_beats_impedance(presses) -> None:
    for noise in (False, True):
        fp, imp = presses[("force_position", noise)], presses[("impedance", noise)]
        assert abs(fp.steady_force_n - 5.0) < 0.25
        assert fp.settling_time_s < 3.0
        # Impedance holds the pose at contact: the gripper spring and pads compress and it
        # settles short of F_d (Eq. 3 has no force feedback).
        assert abs(imp.steady_force_n - 5.0) > 2 * abs(fp.steady_force_n - 5.0)


def test_tcp_wrench_inverts_jacobian_transpose() -> None:
    rng = np.random.default_rng(1)
    jac = rng.normal(size=(6, 7))
    wrench = rng.normal(size=6)
    assert np.allclose(tcp_wrench(jac, jac.T @ wrench), wrench, atol=1e-6)


def test_orientation_error_is_rotation_vector() -> None:
    rot = np.eye(3)
    angle = 0.01
    target = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    assert np.allclose(orientation_error(rot, target), [0, 0, angle], atol=1e-12)


def test_encoder_quantisation_and_ideal_sensors() -> None:
    step = 2 * np.pi / 2**20
    q = np.array([0.3 * step, 0.6 * step])
    assert np.allclose(quantise(q, 2**20), [0.0, step])
    assert ArmSensorConfig.ideal().is_ideal and not ArmSensorConfig().is_ideal
    with pytest.raises(ConfigError, match="torque_noise_std"):
        ArmSensorConfig(torque_noise_std=-1)


def test_joint_target_outside_limits_names_the_joint() -> None:
    q = np.array(HOME_Q)
    q[3] = 0.5
    with pytest.raises(LimitError, match=r"joint4 target 0.5000 rad outside its limit \[-3.0718, -0.0698\]"):
        require_joint_target(q)


def test_torque_saturation_is_reported() -> None:
    scene = build_scene(SceneConfig(n_conductors=0))
    scene.reset()
    ctrl = ArmController(scene.model, names.ARM, ArmControllerConfig(sensors=ArmSensorConfig.ideal()))
    q = np.array(HOME_Q)
    q[0] += 1.0  # a 1 rad step: kp 600 asks 600 N m of an 87 N m joint
    ctrl.hold_joints(q)
    for _ in range(5):
        ctrl.step(scene.model, scene.data)
    assert ctrl.saturation.periods == 5
    assert "joint1" in ctrl.saturation.summary()
    assert np.all(np.abs(scene.data.ctrl[ctrl.index.actuators]) <= 87.0 + 1e-9)


def test_force_target_axis_must_be_unit() -> None:
    with pytest.raises(ConfigError, match="unit vector"):
        ForceTarget(np.array([0.0, 0.0, -2.0]), 5.0)


def test_control_rate_must_divide_timestep() -> None:
    with pytest.raises(ConfigError, match="whole number"):
        ArmControllerConfig(rate_hz=3000.0).substeps(1e-4)


def test_control_check_cli_json(capsys) -> None:
    assert main(["control-check", "--stage", "round_trip", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["passed"] == {"round_trip": True}
    assert out["results"]["round_trip"]["max_position_error_m"] <= 1e-9


def test_control_check_rejects_unknown_stage(capsys) -> None:
    assert main(["control-check", "--stage", "nope"]) == 2
    assert "valid: path, descent, press, round_trip, tracking" in capsys.readouterr().err


def test_plant_torque_sensors_read_link_side_torque() -> None:
    """tau_J = M_link ddq + c + g at rest under gravity hold: the model the estimate uses."""
    scene = build_scene(SceneConfig(n_conductors=0))
    scene.reset()
    ctrl = ArmController(scene.model, names.ARM, ArmControllerConfig(sensors=ArmSensorConfig.ideal()))
    mujoco.mj_step(scene.model, scene.data)
    meas = ctrl.sensors.read(scene.model, scene.data, 1e-3)
    ctrl.nominal.load(meas.q, meas.dq)
    # at rest M_link ddq drops out: c + g, the model's bias force (mj_rne)
    assert np.allclose(meas.tau_J, ctrl.nominal.batch.rne_bias()[0], atol=0.05)
