"""The simulator's exact cameras, to score calibration and vision against; the cell itself
never uses them (it works from calibrated :class:`~serpar.vision.camera.CameraModel`)."""

from __future__ import annotations

import mujoco
import numpy as np

from serpar.vision.camera import CameraModel

MJ_TO_CV = np.diag([1.0, -1.0, -1.0])
"""MuJoCo cameras look along -z with y up; OpenCV cameras look along +z with y down."""


def true_camera(model: mujoco.MjModel, data: mujoco.MjData, name: str,
                size: tuple[int, int] | None = None) -> CameraModel:
    """The simulator's exact camera (for scoring only): no distortion, centred principal point."""
    cam = model.camera(name)
    full = tuple(int(v) for v in model.cam_resolution[cam.id])
    w, h = size or full
    sensor = model.cam_sensorsize[cam.id]
    f = model.cam_intrinsic[cam.id][:2]
    fx, fy = f[0] / sensor[0] * w, f[1] / sensor[1] * h
    K = np.array([[fx, 0, (w - 1) / 2], [0, fy, (h - 1) / 2], [0, 0, 1.0]])
    rot = data.cam_xmat[cam.id].reshape(3, 3) @ MJ_TO_CV
    return CameraModel(name, (w, h), K, np.zeros(5), rot, data.cam_xpos[cam.id].copy())
