"""Offscreen rendering of the scene's cameras (real MuJoCo pixels, EGL by default)."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np

from serpar.errors import ConfigError, UnknownNameError
from serpar.sim.cameras import SENSOR_PIXELS

OVERVIEW = "overview"
"""A free camera for pictures of the whole cell (not one of the stereo cameras)."""
MIN_SIZE, MAX_SIZE = 16, SENSOR_PIXELS
_ASPECT = SENSOR_PIXELS[0] / SENSOR_PIXELS[1]


def resolve_size(camera: str, width: int | None, height: int | None) -> tuple[int, int]:
    """Image size for `camera`; stereo cameras keep the sensor's 4:3 aspect (their intrinsics)."""
    if width is None and height is None:
        width, height = (1280, 960) if camera == OVERVIEW else SENSOR_PIXELS
    elif width is None:
        width = round(height * _ASPECT)  # type: ignore[operator]
    elif height is None:
        height = round(width / _ASPECT)
    assert width is not None and height is not None
    if not (MIN_SIZE <= width <= MAX_SIZE[0] and MIN_SIZE <= height <= MAX_SIZE[1]):
        raise ConfigError(f"image size {width}x{height} out of range: width {MIN_SIZE}..{MAX_SIZE[0]}, "
                          f"height {MIN_SIZE}..{MAX_SIZE[1]}")
    if camera != OVERVIEW and abs(width / height - _ASPECT) > 0.01:
        raise ConfigError(f"image size {width}x{height}: camera {camera!r} has a 4:3 sensor; "
                          "use e.g. 2048x1536, 1024x768 or 640x480")
    return width, height


def _overview_camera() -> mujoco.MjvCamera:
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = (0.42, 0.06, 0.28)
    cam.distance, cam.azimuth, cam.elevation = 1.55, -140.0, -24.0
    return cam


class CameraRenderer:
    """Renders named cameras of one model; reuses one GL context per image size."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self.names = [OVERVIEW] + [model.camera(i).name for i in range(model.ncam)]

    def render(self, data: mujoco.MjData, camera: str, width: int | None = None,
               height: int | None = None) -> np.ndarray:
        """RGB image (H, W, 3) uint8 from `camera`."""
        if camera not in self.names:
            raise UnknownNameError("camera", camera, self.names)
        w, h = resolve_size(camera, width, height)
        renderer = self._renderers.get((w, h))
        if renderer is None:
            renderer = self._renderers[(w, h)] = mujoco.Renderer(self.model, h, w)
        renderer.update_scene(data, _overview_camera() if camera == OVERVIEW else camera)
        return renderer.render().copy()

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()


def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write an RGB image as PNG (parent folders created)."""
    from PIL import Image

    out = Path(path)
    if out.suffix.lower() != ".png":
        raise ConfigError(f"output {out} must end in .png")
    out.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(out)
    return out
