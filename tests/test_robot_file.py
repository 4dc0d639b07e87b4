"""Any arm from its URDF/MJCF (``--robot FILE``): the nominal chain read from the model file,
its joint count and limits in the readers, the geometric campaign of each shipped arm and the
commands end to end."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from arm_cal_support import static_position_recording

from serpar.assets import asset_path
from serpar.calibration.panda_data import load_panda_folder
from serpar.calibration.robot_campaign import noise_bound_rms, robot_calibration
from serpar.cli.entry import main
from serpar.errors import ConfigError, IdentificationError
from serpar.kinematics.mdh import forward, panda_chain
from serpar.kinematics.robot import PANDA
from serpar.sim.arm_measurements import PositionSet
from serpar.sim.plants.static_arm import (
    GeometricCampaignConfig,
    build_plant,
    tool_points,
)
from serpar.sim.robot_file import load_robot

PANDA_XML = str(asset_path("arm", "panda.xml"))
IIWA = str(asset_path("iiwa14", "iiwa14.xml"))
UR5E = str(asset_path("ur5e", "ur5e.urdf"))
TOOL = (0.0, 0.06, 0.12)


def _random_q(robot, n: int = 200, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform(robot.q_min, robot.q_max, (n, robot.n_joints))


def _dh_standard(q: np.ndarray, d, a, alpha) -> np.ndarray:
    """Flange poses of a standard (distal) DH table, written out independently of serpar."""
    out = np.empty((len(q), 4, 4))
    for k, row in enumerate(q):
        t = np.eye(4)
        for th, di, ai, al in zip(row, d, a, alpha):
            ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(al), math.sin(al)
            t = t @ np.array([[ct, -st * ca, st * sa, ai * ct], [st, ct * ca, -ct * sa, ai * st],
                              [0.0, sa, ca, di], [0.0, 0.0, 0.0, 1.0]])
        out[k] = t
    return out


def test_panda_mjcf_reads_back_the_panda_chain() -> None:
    robot = load_robot(PANDA_XML)
    assert robot.n_joints == 7 and robot.q_min == PANDA.q_min and robot.q_max == PANDA.q_max
    chain, ref = robot.chain(TOOL), panda_chain(TOOL)
    q = _random_q(robot)
    gap = np.abs(forward(chain, chain.values(), q) - forward(ref, ref.values(), q)).max()
    assert gap < 1e-9
    # the Panda's MJCF bodies are its MD-H frames: the table itself comes back
    assert chain.names == ref.names
    assert np.allclose(chain.nominal, ref.nominal, atol=1e-12)
    assert PANDA.chain(TOOL) == ref


def test_iiwa14_matches_its_published_dh_table() -> None:
    robot = load_robot(IIWA)
    assert (robot.name, robot.n_joints) == ("iiwa14", 7)
    assert robot.q_max == pytest.approx(np.radians([170, 120, 170, 120, 170, 120, 175]), abs=1e-5)
    q = _random_q(robot)
    chain = robot.chain()
    dh = _dh_standard(q, (0.36, 0, 0.42, 0, 0.4, 0, 0.126), (0,) * 7,
                      (-math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2,
                       math.pi / 2, 0))
    got = forward(chain, chain.values(), q)
    assert np.abs(got[:, :3, 3] - dh[:, :3, 3]).max() < 1e-9
    assert np.abs(got[:, :3, 2] - dh[:, :3, 2]).max() < 1e-9  # the flange's approach axis


def test_ur5e_urdf_matches_its_published_dh_table() -> None:
    robot = load_robot(UR5E)
    assert (robot.name, robot.n_joints) == ("ur5e", 6)
    assert robot.q_min == pytest.approx((-2 * math.pi,) * 6)
    q = _random_q(robot)
    chain = robot.chain()
    dh = _dh_standard(q, (0.1625, 0, 0, 0.1333, 0.0997, 0.0996), (0, -0.425, -0.3922, 0, 0, 0),
                      (math.pi / 2, 0, 0, math.pi / 2, -math.pi / 2, 0))
    assert np.abs(forward(chain, chain.values(), q) - dh).max() < 1e-9


@pytest.mark.parametrize("path", [IIWA, UR5E])
def test_nominal_plant_is_the_chain(path: str) -> None:
    """The campaign's MuJoCo plant without errors puts the SMR where the nominal chain does."""
    robot = load_robot(path)
    cfg = GeometricCampaignConfig()
    model, qpos = build_plant(robot, cfg, errors=False)
    q = _random_q(robot, 50)
    chain = robot.chain(cfg.tool_offset_m)
    assert np.abs(tool_points(model, qpos, q) - forward(chain, chain.values(), q)[:, :3, 3]
                  ).max() < 1e-9


BRANCHED = """<mujoco model="y"><worldbody><body name="b0"><inertial pos="0 0 0" mass="1"
 diaginertia="1 1 1"/><joint name="j0" axis="0 0 1"/>
 <body name="left" pos="0 0.1 0"><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
 <joint name="jl" axis="1 0 0"/></body>
 <body name="right" pos="0 -0.1 0"><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
 <joint name="jr" axis="1 0 0"/></body></body></worldbody></mujoco>"""
PRISMATIC = """<mujoco model="p"><worldbody><body name="b0"><inertial pos="0 0 0" mass="1"
 diaginertia="1 1 1"/><joint name="j0" axis="0 0 1"/>
 <body name="b1" pos="0 0 0.3"><inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
 <joint name="lift" type="slide" axis="0 0 1"/><site name="flange"/></body></body>
 </worldbody></mujoco>"""


@pytest.mark.parametrize("text, words", [(BRANCHED, "not a single serial chain: joint(s) 'jl'"),
                                         (PRISMATIC, "a slide (prismatic) joint 'lift'")])
def test_non_serial_or_prismatic_model_is_one_line(tmp_path, text: str, words: str) -> None:
    path = tmp_path / "arm.xml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"--robot .*arm\.xml") as err:
        load_robot(path)
    assert words in str(err.value) and "\n" not in str(err.value)


def _write_points(folder: Path, n_joints: int, q_of) -> None:
    for place in ("front", "back"):
        (folder / place).mkdir(parents=True)
        for hole in ("hole_0.csv", "hole_1.csv"):
            rows = [",".join(f"{v:.6f}" for v in q_of(n_joints)) for _ in range(4)]
            (folder / place / hole).write_text("\n".join(rows) + "\n")


def test_six_joint_point_file_needs_a_six_joint_robot(tmp_path) -> None:
    rng = np.random.default_rng(1)
    _write_points(tmp_path, 6, lambda n: rng.uniform(-1.0, 1.0, n))
    ur5e = load_robot(UR5E)
    data = load_panda_folder(tmp_path, ur5e)
    assert data.point_set(("front",)).q.shape == (8, 6)
    with pytest.raises(IdentificationError, match=r"expected 7 joint angles \(panda\), got 6 "
                       r"values; another arm: give its URDF/MJCF with --robot FILE"):
        load_panda_folder(tmp_path)


def test_out_of_range_angle_names_the_robot() -> None:
    iiwa = load_robot(IIWA)
    q = np.zeros((3, 7))
    q[1, 5] = 3.9
    with pytest.raises(IdentificationError) as err:
        PositionSet(q, np.full((3, 3), 0.5), robot=iiwa)
    msg = str(err.value)
    assert "pose 1: joint 6 at 3.9000 rad is outside its range -2.094..2.094 rad of iiwa14 (from " in msg
    assert IIWA in msg and "--robot" not in msg  # the arm is named: no hint


@pytest.mark.parametrize("path", [IIWA, UR5E])
def test_geometric_campaign_recovers_to_the_noise_floor(path: str) -> None:
    """Hidden errors of the Panda campaign's size (0.2 mm / 0.5 mrad per link, 1 mm / 1 mrad
    base, 0.5 mm SMR): the nominal model misses by ~3 mm; the calibrated one's held-out RMS
    against the 15 um tracker sits at its floor sigma sqrt(3) = 26.0 um (measured 26.6 um
    iiwa14, 26.3 um UR5e; the rigid Panda 27.7 um), and against the truth at the parameter
    noise sigma sqrt(p / N) = 15 um sqrt(31 / 150) = 6.8 um (measured 6.2 / 7.2 um)."""
    robot = load_robot(path)
    cfg = GeometricCampaignConfig()
    res = robot_calibration(robot, cfg)
    bound = noise_bound_rms(cfg.tracker_sigma_m)
    nominal, cal = res.row("uncalibrated"), res.row("geometric")
    assert nominal.verify.rms > 2e-3
    assert cal.verify.rms < 1.06 * bound
    p, n = cal.calibration.report.rank, cfg.n_train
    assert cal.verify_truth.rms < 1.2 * cfg.tracker_sigma_m * math.sqrt(p / n)
    assert 0.85 < cal.calibration.residual_rms < 1.15


def test_calibrate_arm_robot_end_to_end(capsys) -> None:
    assert main(["calibrate", "arm", "--robot", UR5E, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robot"]["name"] == "ur5e" and out["robot"]["n_joints"] == 6
    assert out["rows"]["geometric"]["verify"]["rms_m"] < 1.06 * out["noise_bound_rms_m"]
    assert main(["calibrate", "arm", "--robot", UR5E, "--model", "gravity"]) == 2
    assert "only the Panda has here" in capsys.readouterr().err


def test_diagnose_robot_end_to_end(tmp_path, capsys) -> None:
    rec = static_position_recording(UR5E, tmp_path / "ur")
    assert main(["diagnose", str(rec), "--robot", UR5E, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["robot"] == {"name": "ur5e", "source": UR5E}
    assert out["findings"][0]["effect"] == "geometric"
    # 47 sigma before (the hidden ~0.7 mm per axis), at the noise after (measured 0.94)
    assert out["heldout_rms_whitened_before"] > 20
    assert out["heldout_rms_whitened_after"] < 1.2
    # without --robot the Panda reads it: one line naming the joint count
    assert main(["diagnose", str(rec)]) == 2
    assert "ur5e" not in (err := capsys.readouterr().err) and "panda has 7 joints" in err


def test_diagnose_robot_names_both_joint_counts(tmp_path, capsys) -> None:
    """A 7-joint recording diagnosed as the 6-joint UR5e: one line naming both counts."""
    assert main(["twin", "--effect", "none", "--domain", "arm_dynamics", "--seed", "1",
                 "--out", str(tmp_path / "dyn")]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(tmp_path / "dyn"), "--robot", UR5E]) == 2
    err = capsys.readouterr().err.strip()
    assert "the recording has 7 joints (q1..q7), the robot ur5e has 6" in err
    assert "\n" not in err
