"""The stereo cameras as the Stewart calibration's pose source (calibration/stewart_stereo.py, issue 6).

One campaign in the MuJoCo cell (seed 000 Table 5's hidden errors, 10 poses chosen in the top
pair's view for conditioning, 1024 px frames with sensor noise and lighting variation, the
cached full-size camera calibration) measures every pose from rendered pixels; the tests score
it against the simulator's truth and calibrate from it. The identified model is then scored on
30 random verification poses through the exact kinematics of the built platform, registered at
home as the cell does (the in-cell scoring of `serpar calibrate stewart --source stereo` is the
CLI's; the leg servos settle within a few um of the kinematics, far below the errors here).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from serpar.calibration.stewart_calibration import (
    StewartCalibrationConfig,
    measured_noise,
    pose_errors,
)
from serpar.calibration.stewart_campaign import random_poses
from serpar.calibration.stewart_identification import identify_lm
from serpar.calibration.stewart_poses import optimal_poses, predicted_error_rms
from serpar.calibration.stewart_stereo import (
    StereoConfig,
    planning_view,
    regauge,
    stereo_campaign,
    top_pair,
    visible_random_poses,
)
from serpar.controllers.plate_commander import inverse, transform
from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import forward_kinematics, inverse_kinematics
from serpar.kinematics.stewart_table import table5_errors
from serpar.sim.scene import SceneConfig
from serpar.sim.stewart import StewartConfig, built_geometry, home_strokes

pytestmark = [pytest.mark.xdist_group("calibrated"), pytest.mark.slow]
STEREO = StereoConfig(width=1024)
HIDDEN = table5_errors()
CELL = SceneConfig()
GEOMETRY = CELL.stewart.geometry()
MAX_POSITION_M, MAX_ANGLE_DEG = 0.099e-3, 0.139
"""Per pose, 3-D: `serpar vision-check`'s step-2 figures at 1024 px (hole centre p95, hole axis
max). The plate pose is fitted to all 36 holes and the edges at once, so it should do better
than one hole's p95; the pose is measured relative to the home shot, which adds that shot's
error, so no tighter bound follows from the camera figures."""


@pytest.fixture(scope="module")
def campaign():
    poses = optimal_poses(GEOMETRY, 10, visible_random_poses(200, 3, GEOMETRY, planning_view(STEREO, CELL)))
    cell = dataclasses.replace(CELL, stewart=dataclasses.replace(CELL.stewart, joint_errors=HIDDEN))
    return poses, stereo_campaign(cell, *poses, None, STEREO, top_pair(STEREO), seed=0)


def _registered_truth(stewart: StewartConfig, believed: np.ndarray | None, poses) -> tuple[np.ndarray, np.ndarray]:
    """Where the platform with HIDDEN errors stands, commanded through the `believed` model, in
    the frame the model registers at its home strokes (stereo_campaign's scoring frame)."""
    model, model_dl = built_geometry(dataclasses.replace(stewart, joint_errors=believed))
    built, dl = built_geometry(dataclasses.replace(stewart, joint_errors=HIDDEN))
    home = home_strokes(stewart)
    x_h = transform(*forward_kinematics(model, home + model_dl, stewart.home_pos)[1::-1])
    p_h = transform(*forward_kinematics(built, home + dl, stewart.home_pos)[1::-1])
    frame = x_h @ inverse(p_h)
    out = []
    for s, p, r in zip(inverse_kinematics(model, *poses) - model_dl, *poses):
        out.append(frame @ transform(*forward_kinematics(built, s + dl, p, r)[1::-1]))
    out = np.array(out)
    return out[:, :3, 3], out[:, :3, :3]


def test_stereo_poses_agree_with_the_true_poses(campaign):
    poses, result = campaign
    assert result.skipped == () and len(result.kept) == len(poses[0])  # planned in view: all measured
    dist = np.linalg.norm(result.position_error, axis=1)
    angle = np.degrees(np.linalg.norm(result.angle_error, axis=1))
    assert dist.max() < MAX_POSITION_M, dist
    assert angle.max() < MAX_ANGLE_DEG, angle
    # the home shot's own (absolute) error, ~0.17 mm at 1024 px, mostly depth, is common to every
    # pose and cancels: it is reported, not bounded here
    assert result.registration_error is not None


def test_stereo_calibration_reduces_the_platform_error(campaign):
    _, result = campaign
    verify = random_poses(30, 1, GEOMETRY)
    before = pose_errors(*_registered_truth(CELL.stewart, None, verify), *verify)
    ident = identify_lm(GEOMETRY, result.meas)
    after = pose_errors(*_registered_truth(CELL.stewart, regauge(ident.errors, GEOMETRY), verify), *verify)
    assert after.rms < before.rms, (after.rms, before.rms)  # measured: 0.33 -> 0.21 mm


@pytest.mark.xfail(strict=True, reason="10 stereo poses at 1024 px leave the worst orientation error at the "
                                       "+-40 mm / +-5 deg verification poses no better than uncalibrated "
                                       "(the pair's 0.028 deg per axis through a Jacobian this small set "
                                       "conditions poorly); the 20-pose 2048 px CLI run does reduce it")
def test_stereo_calibration_reduces_the_worst_orientation_error(campaign):
    _, result = campaign
    verify = random_poses(30, 1, GEOMETRY)
    before = pose_errors(*_registered_truth(CELL.stewart, None, verify), *verify)
    ident = identify_lm(GEOMETRY, result.meas)
    after = pose_errors(*_registered_truth(CELL.stewart, regauge(ident.errors, GEOMETRY), verify), *verify)
    assert np.abs(after.rotation).max() < np.abs(before.rotation).max()


def test_stereo_calibration_is_within_the_noise_predicted_bound(campaign):
    poses, result = campaign
    verify = random_poses(30, 1, GEOMETRY)
    ident = identify_lm(GEOMETRY, result.meas)
    after = pose_errors(*_registered_truth(CELL.stewart, regauge(ident.errors, GEOMETRY), verify), *verify)
    predicted = predicted_error_rms(GEOMETRY, poses, verify, *measured_noise(result))
    assert after.rms < 1.5 * predicted, (after.rms, predicted)


def test_regauge_keeps_the_leg_closure_and_centres_the_base_joints():
    e = np.random.default_rng(0).uniform(-1e-3, 1e-3, (6, 7))
    g = regauge(e, GEOMETRY)
    assert np.allclose(g[:, :4], e[:, :4])  # dl and dP are frame-free
    moved = np.asarray(GEOMETRY.base_joints) + g[:, 4:7]
    assert np.allclose(moved.mean(axis=0), np.mean(GEOMETRY.base_joints, axis=0), atol=1e-12)
    # the base joint distances (all the legs see of the base) are kept
    d = lambda b: np.linalg.norm(b[:, None] - b[None], axis=-1)
    assert np.allclose(d(moved), d(np.asarray(GEOMETRY.base_joints) + e[:, 4:7]), atol=1e-12)


@pytest.mark.parametrize("kwargs, needle", [({"width": 800}, "valid: 2048, 1024, 512"),
                                            ({"max_offset_m": 0.02}, "valid 0..0.01")])
def test_bad_stereo_config_names_the_choices(kwargs, needle):
    with pytest.raises(ConfigError, match=needle):
        StereoConfig(**kwargs)
    with pytest.raises(ConfigError, match="valid: cell, kinematic, stereo"):
        StewartCalibrationConfig(source="camera")
