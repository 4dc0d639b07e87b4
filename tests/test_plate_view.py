"""Step 2 needs the whole hole grid in both top images. The platform carries the plate up to
35 mm from home to present a corner hole at the station, and from the far corners (holes
30-35 of the default cell) the grid leaves the left edge of the images: the last cycles of a
36-hole episode then ended vision_miss until the cycle learnt to bring the plate back."""

import mujoco
import numpy as np
import pytest

from serpar.calibration.camera_truth import true_camera
from serpar.controllers.plate_commander import transform
from serpar.sim.scene import SceneConfig, build_scene
from serpar.tasks.episode_steps import STATION_ENTRY, TOP
from serpar.vision.imaging import ImagingConfig
from serpar.vision.layout import plate_in_view, plate_layout

CFG = SceneConfig()


@pytest.fixture(scope="module")
def cameras():
    scene = build_scene(CFG)
    mujoco.mj_kinematics(scene.model, scene.data)
    size = ImagingConfig(width=2048).size
    return tuple(true_camera(scene.model, scene.data, name, size) for name in TOP)


def _holes_in_plate() -> np.ndarray:
    xy = CFG.baseplate.hole_centres().reshape(-1, 2)
    return np.c_[xy, np.full(len(xy), CFG.baseplate.thickness)]


def _presenting(hole: int) -> np.ndarray:
    """Plate pose (untilted) with `hole`'s entry at the insertion station."""
    holes = _holes_in_plate()
    return transform(np.eye(3), STATION_ENTRY - holes[hole])


def _in_view(pose: np.ndarray, cameras) -> bool:
    return plate_in_view(plate_layout(CFG), CFG.baseplate, pose, _holes_in_plate(), cameras,
                         above=CFG.conductor.body_length)


def test_the_plate_at_home_is_in_view(cameras):
    assert _in_view(transform(np.eye(3), np.array(plate_layout(CFG).origin)), cameras)


@pytest.mark.parametrize("hole", [0, 14, 21, 29])
def test_the_plate_presenting_a_near_hole_stays_in_view(cameras, hole):
    assert _in_view(_presenting(hole), cameras)


@pytest.mark.parametrize("hole", [30, 35])
def test_the_plate_presenting_a_far_corner_leaves_the_view(cameras, hole):
    assert not _in_view(_presenting(hole), cameras)


def test_a_plate_beyond_the_search_region_is_not_in_view(cameras):
    pose = transform(np.eye(3), np.array(plate_layout(CFG).origin) + [0.0, 0.0, 0.03])
    assert not _in_view(pose, cameras)
