"""The two stereo pairs of seed 000 §5.2: 3.2 MP industrial cameras (Hikvision MV-CS032-10GC class).

Sensor: 2048 x 1536 pixels of 3.45 um (7.07 x 5.30 mm). Intrinsics are given to
MuJoCo physically (sensor size + focal length), so renders at any resolution
with the same 4:3 aspect follow the same pinhole model. Each camera looks at
its pair's target from its own position (a converging pair).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError

SENSOR_PIXELS = (2048, 1536)
PIXEL_PITCH = 3.45e-6


@dataclass(frozen=True)
class StereoPairConfig:
    """One converging stereo pair [m]."""

    name: str
    target: tuple[float, float, float]
    """Point both cameras look at (world frame)."""
    centre: tuple[float, float, float]
    """Midpoint between the two optical centres."""
    baseline_dir: tuple[float, float, float]
    """Direction from the left to the right camera."""
    baseline: float
    focal_length: float
    """Lens focal length."""

    def __post_init__(self) -> None:
        if self.baseline <= 0 or not 0.004 <= self.focal_length <= 0.1:
            raise ConfigError(f"pair {self.name}: baseline > 0 and focal length in 4..100 mm")

    def camera_names(self) -> tuple[str, str]:
        return (f"{self.name}_left", f"{self.name}_right")

    def pixel_size_at_target(self) -> float:
        """Footprint of one pixel on a plane at the target distance [m]."""
        dist = float(np.linalg.norm(np.subtract(self.target, self.centre)))
        return PIXEL_PITCH * dist / self.focal_length


TOP_PAIR = StereoPairConfig(
    name="top", target=(0.60, 0.135, 0.27), centre=(0.60, 0.135, 0.92),
    baseline_dir=(0.0, 1.0, 0.0), baseline=0.20, focal_length=0.012,
)
"""Over the tray and the baseplate: finds conductors (step 1) and empty holes (step 2)."""
INSPECT_PAIR = StereoPairConfig(
    name="inspect", target=(0.45, -0.25, 0.35), centre=(0.45, -0.45, 0.33),
    baseline_dir=(1.0, 0.0, 0.0), baseline=0.06, focal_length=0.025,
)
"""In-hand inspection (step 4) of the grasped conductor against a backlight."""
DEFAULT_PAIRS = (TOP_PAIR, INSPECT_PAIR)


def _look_at_xyaxes(pos: np.ndarray, target: np.ndarray, up_hint: np.ndarray) -> list[float]:
    """MuJoCo camera xyaxes: camera looks along -z, x right, y up in the image."""
    forward = target - pos
    forward /= np.linalg.norm(forward)
    x = np.cross(forward, up_hint)
    if np.linalg.norm(x) < 1e-9:
        raise ConfigError("camera up hint is parallel to its viewing direction")
    x /= np.linalg.norm(x)
    y = np.cross(x, forward)
    return [*x, *y]


def add_stereo_pair(spec: mujoco.MjSpec, pair: StereoPairConfig) -> None:
    """Add both cameras of `pair` (with a small visual housing each) to the world body."""
    centre, target = np.array(pair.centre), np.array(pair.target)
    direction = np.array(pair.baseline_dir, dtype=float)
    direction /= np.linalg.norm(direction)
    view = target - centre
    # A downward pair has its long image side along the baseline (world y here: tray and plate
    # side by side), image up = world -x; a horizontal pair keeps world +z up.
    up_hint = np.array([-1.0, 0.0, 0.0]) if abs(view[2]) > 0.7 * np.linalg.norm(view) else np.array([0.0, 0.0, 1.0])
    for name, sign in zip(pair.camera_names(), (-0.5, 0.5)):
        pos = centre + sign * pair.baseline * direction
        cam = spec.worldbody.add_camera(name=name, pos=pos.tolist(),
                                        xyaxes=_look_at_xyaxes(pos, target, up_hint))
        cam.resolution = list(SENSOR_PIXELS)
        cam.sensor_size = [SENSOR_PIXELS[0] * PIXEL_PITCH, SENSOR_PIXELS[1] * PIXEL_PITCH]
        cam.focal_length = [pair.focal_length, pair.focal_length]
        housing = spec.worldbody.add_body(name=f"{name}_housing", pos=pos.tolist(),
                                          xyaxes=_look_at_xyaxes(pos, target, up_hint))
        housing.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.015, 0.015, 0.03],
                         pos=[0, 0, 0.035], rgba=[0.2, 0.2, 0.22, 1], contype=0, conaffinity=0)
