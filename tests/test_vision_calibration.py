"""Stereo calibration from rendered checkerboard frames, registered to the arm base, scored
against the simulator's true cameras. Bounds are the errors measured at full size with sensor
noise and lighting variation, with margin; what they mean downstream is in the step tests."""

from __future__ import annotations

import cv2
import mujoco
import numpy as np
import pytest

from serpar.calibration.camera_truth import true_camera
from serpar.calibration.camera_views import INSPECT_VOLUME, board_poses
from serpar.sim.calibration_board import INSPECT_BOARD, TOP_BOARD
from serpar.sim.cameras import INSPECT_PAIR
from serpar.sim.poses import solve_tcp_pose
from serpar.sim.scene import SceneConfig, build_scene
from serpar.vision.checkerboard import find_corners
from serpar.vision.errors import CalibrationError, ImageError, TargetNotFound
from serpar.vision.imaging import Camera, ImagingConfig
from serpar.vision.stereo_calibration import Observation, calibrate_pair

pytestmark = [pytest.mark.xdist_group("calibrated"), pytest.mark.slow]


def test_top_pair_calibration(calibrated_top):
    run = calibrated_top
    assert run.calibration.rms_px["bundle"] < 0.1
    assert run.calibration.rectified_row_error_px < 0.1
    assert run.calibration.views_used["both"] >= 12
    s = run.score
    assert abs(s["baseline_error_mm"]) < 0.05
    for side in ("left", "right"):
        assert abs(s[side]["fx_error_pct"]) < 0.1 and s[side]["rotation_error_deg"] < 0.05
    # What the detectors inherit: 3-D error over the calibrated volume from perfect pixels.
    assert s["triangulation_error_mm"]["max"] < 0.05


def test_inspect_pair_calibration(calibrated_inspect):
    run = calibrated_inspect
    assert run.calibration.rms_px["bundle"] < 0.15
    assert run.calibration.views_used["both"] >= 10
    assert abs(run.score["baseline_error_mm"]) < 0.1
    assert run.score["triangulation_error_mm"]["max"] < 0.01


@pytest.fixture(scope="module")
def board_scene():
    scene = build_scene(SceneConfig(n_conductors=0, calibration_board=INSPECT_BOARD))
    centre, rot = board_poses(INSPECT_PAIR, INSPECT_VOLUME, seed=3)[0]
    _, pos_tb = INSPECT_BOARD.tcp_to_board()
    scene.data.qpos[scene.arm_qpos_adr] = solve_tcp_pose(scene, centre - rot @ pos_tb, rotation=rot)
    mujoco.mj_forward(scene.model, scene.data)
    return scene


def test_corner_order_follows_the_board(board_scene):
    """Corner 0 is the board's (-x, -y) inner corner and the board faces the camera, whichever
    order OpenCV returned the corners in."""
    m, d = board_scene.model, board_scene.data
    frame = Camera(m, ImagingConfig(), seed=1).shoot(d, ("inspect_left",))["inspect_left"]
    corners = find_corners(frame, INSPECT_BOARD)
    cam = true_camera(m, d, "inspect_left")
    body = m.body("calibration_board").id
    pts = d.xpos[body] + INSPECT_BOARD.corner_points() @ d.xmat[body].reshape(3, 3).T
    assert np.abs(corners - cam.project(pts)).max() < 0.3  # every corner, in order, sub-pixel


def test_no_board_is_a_typed_failure():
    scene = build_scene(SceneConfig(n_conductors=0))
    frame = Camera(scene.model, ImagingConfig(width=1024), seed=0).shoot(scene.data, ("top_left",))["top_left"]
    with pytest.raises(TargetNotFound, match="checkerboard"):
        find_corners(frame, TOP_BOARD)


def test_too_few_views_is_a_typed_failure():
    obs = [Observation(np.eye(3), np.zeros(3), None, None)] * 10
    with pytest.raises(CalibrationError, match="need >= 6"):
        calibrate_pair(obs, TOP_BOARD, (2048, 1536), ("top_left", "top_right"))


def test_wrong_images_are_one_line_errors():
    scene = build_scene(SceneConfig(n_conductors=0))
    cam = true_camera(scene.model, scene.data, "top_left")
    with pytest.raises(ImageError, match="1024x768, the camera model is 2048x1536"):
        cam.check_image(np.zeros((768, 1024, 3), np.uint8))
    with pytest.raises(ImageError, match="uint8"):
        cam.check_image(np.zeros((1536, 2048, 3), np.float32))
    assert cv2.Rodrigues(cam.rot)[0].shape == (3, 1)
