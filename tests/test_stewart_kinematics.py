"""Stewart kinematics (serpar.kinematics.stewart_kinematics): IK/FK, Jacobian, hinge angles, limits."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from serpar.checks.stewart_checks import ik_fk_round_trip, valid_poses
from serpar.errors import ConfigError, LimitError
from serpar.kinematics.rotations import euler_to_rot, quat_to_rot, rotation_angle, so3_exp
from serpar.kinematics.stewart_kinematics import (
    StewartGeometry,
    check_pose,
    forward_kinematics,
    hinge_angles_deg,
    inverse_kinematics,
    jacobian,
    require_pose,
    singularity_measure,
)
from serpar.sim.stewart import StewartConfig, load_joint_table, stewart_geometry, stroke_for_pose

GEOM = stewart_geometry()
HOME = np.array(GEOM.home_pos)


def test_round_trip_1000_valid_poses_within_1e_9() -> None:
    r = ik_fk_round_trip(GEOM, n=1000, seed=0)
    assert r.poses == 1000
    assert r.max_position_error_m <= 1e-9, r
    assert r.max_rotation_error_rad <= 1e-9, r
    assert r.max_stroke_residual_m < 1e-12  # the returned pose reproduces the strokes
    assert r.max_iterations <= 10  # Newton from home converges quadratically


def test_batched_ik_equals_single_and_sim_stewart_delegates() -> None:
    pos, rot = valid_poses(GEOM, 50, seed=1)
    batched = inverse_kinematics(GEOM, pos, rot)
    assert batched.shape == (50, 6)
    for k in (0, 17, 49):
        np.testing.assert_array_equal(batched[k], inverse_kinematics(GEOM, pos[k], rot[k]))
    quat = Rotation.from_matrix(rot[3]).as_quat(scalar_first=True)
    np.testing.assert_allclose(stroke_for_pose(pos[3], quat), batched[3], atol=1e-15)


def test_jacobian_matches_finite_differences() -> None:
    pos, rot = valid_poses(GEOM, 10, seed=2)
    h = 1e-6
    for p, r in zip(pos, rot):
        fd = np.empty((6, 6))
        for k in range(6):
            d = np.zeros(6)
            d[k] = h
            plus = inverse_kinematics(GEOM, p + d[:3], so3_exp(d[3:]) @ r)
            minus = inverse_kinematics(GEOM, p - d[:3], so3_exp(-d[3:]) @ r)
            fd[:, k] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(jacobian(GEOM, p, r), fd, atol=1e-8)


def test_singularity_measure_printed_table_vs_corrected() -> None:
    printed = StewartGeometry(*load_joint_table(swap_legs12=False), GEOM.l_min, GEOM.stroke)
    assert singularity_measure(jacobian(printed, HOME, np.eye(3))) < 1e-7
    home = float(singularity_measure(jacobian(GEOM, HOME, np.eye(3))))
    assert 5e-3 < home < 1e-2  # condition number ~127


def test_fk_raises_on_unreachable_strokes() -> None:
    # Legs 1-3 at 0 and 4-6 at 1 m: the triangle inequality rules it out (joints < 0.6 m apart).
    with pytest.raises(LimitError, match=r"residual .* outside \[0, 1e-12\] m"):
        forward_kinematics(GEOM, np.array([0, 0, 0, 1.0, 1.0, 1.0]))
    with pytest.raises(ConfigError):
        forward_kinematics(GEOM, np.zeros(5))


def test_fk_from_home_recovers_a_far_pose() -> None:
    rot = euler_to_rot(*np.radians([4.0, -4.0, 9.0]))
    pos = np.array([0.05, -0.04, 0.245])
    p, r, it = forward_kinematics(GEOM, inverse_kinematics(GEOM, pos, rot))
    assert np.linalg.norm(p - pos) < 1e-12 and rotation_angle(r, rot) < 1e-10 and it < 10


def test_hinge_definitions_at_home() -> None:
    for definition in ("deflection", "cardan"):
        beta, alpha = hinge_angles_deg(GEOM, HOME, np.eye(3), definition)
        np.testing.assert_allclose(np.r_[beta, alpha], 0, atol=1e-12)
    beta, alpha = hinge_angles_deg(GEOM, HOME, np.eye(3), "normal")
    # 61.872 mm horizontal leg offset over 265 mm: every leg tilts 13.14 deg at home.
    np.testing.assert_allclose(beta, np.degrees(np.arctan2(0.061872, 0.265)), atol=1e-3)
    np.testing.assert_allclose(alpha, beta)
    assert check_pose(GEOM, HOME, np.eye(3), "normal") == []
    with pytest.raises(ConfigError, match="valid: deflection, cardan, normal"):
        hinge_angles_deg(GEOM, HOME, np.eye(3), "vertical")  # type: ignore[arg-type]


def test_cardan_box_contains_deflection_cone() -> None:
    pos, rot = valid_poses(GEOM, 200, seed=4, definition="cardan")
    cone, _ = hinge_angles_deg(GEOM, pos, rot, "deflection")
    box, _ = hinge_angles_deg(GEOM, pos, rot, "cardan")
    assert np.all(box <= cone + 1e-9)  # cos(cone) = cos a cos b: max(|a|, |b|) <= cone


def test_limit_error_names_leg_limit_and_range() -> None:
    with pytest.raises(LimitError, match=r"leg \d stroke 5\d\.\d+ mm outside \[0, 50.8\] mm"):
        require_pose(GEOM, np.array([0, 0, 0.300]), np.eye(3))
    with pytest.raises(LimitError, match=r"leg \d stroke -\d\.\d+ mm outside \[0, 50.8\] mm"):
        require_pose(GEOM, np.array([0, 0, 0.230]), np.eye(3))
    rot = euler_to_rot(*np.radians([-1.0, -3.0, 8.8]))  # within stroke, beta > 20 deg
    problems = check_pose(GEOM, np.array([0.0496, -0.0827, 0.2598]), rot)
    assert problems and all("lower hinge (beta, deflection)" in p and "outside [0, 20] deg" in p
                            for p in problems), problems
    np.testing.assert_allclose(require_pose(GEOM, HOME, np.eye(3)),
                               inverse_kinematics(GEOM, HOME, np.eye(3)))


def test_rotation_helpers_match_references() -> None:
    eps, phi, theta = np.radians([3.0, -4.0, 9.0])
    want = Rotation.from_euler("xyz", [eps, phi, theta]).as_matrix()  # extrinsic x, y, z
    np.testing.assert_allclose(euler_to_rot(eps, phi, theta), want, atol=1e-15)
    quat = np.array([0.9, 0.1, -0.2, 0.3])
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat / np.linalg.norm(quat))
    np.testing.assert_allclose(quat_to_rot(quat), mat.reshape(3, 3), atol=1e-15)
    assert abs(rotation_angle(np.eye(3), so3_exp(np.array([0, 1e-9, 0]))) - 1e-9) < 1e-20


def test_geometry_validation_and_config_link() -> None:
    p, b = load_joint_table()
    with pytest.raises(ConfigError, match="6x3"):
        StewartGeometry(p[:5], b, 0.2468, 0.0508)
    with pytest.raises(ConfigError, match="home_pos"):
        StewartGeometry(p, b, 0.2468, 0.0508, home_pos=(0, 0, 0.5))
    with pytest.raises(ConfigError, match="stroke"):
        StewartGeometry(p, b, 0.2468, -1.0)
    geom = StewartConfig().geometry()
    assert geom == GEOM and hash(geom) == hash(GEOM)
    assert geom.l_min == 0.2468 and geom.stroke == 0.0508
    with pytest.raises(ValueError):
        geom.P[0, 0] = 1.0  # read-only view: the frozen geometry cannot be changed through it
