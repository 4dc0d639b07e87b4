"""Step 5: the Stewart platform moves the baseplate so the chosen hole meets the held journal.

Everything here works from what the cell knows: the platform's *model* (nominal, or with
identified parameters), the poses it has commanded, and what vision measured. The model
relates leg commands to platform poses in the Stewart base frame; one plate measurement by
the top cameras at the start of an episode registers that frame to the arm base frame (the
cameras' frame). From then on the plate moves by the model alone, so the model's errors show
up as misplaced holes unless it is calibrated.

Poses are 4x4 homogeneous transforms; ``a_T_b`` maps b coordinates into a.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import mujoco
import numpy as np

from serpar.controllers.arm_laws import orientation_error
from serpar.controllers.stewart_servo import StewartServo
from serpar.kinematics.rotations import so3_exp
from serpar.kinematics.stewart_kinematics import StewartGeometry, forward_kinematics, require_pose
from serpar.sim import names
from serpar.sim.stewart import MAX_JOINT_ERROR, StewartConfig, built_geometry
from serpar.vision.plate import PlateMeasurement

MIN_RAMP_S = 0.2
RAMP_SPEED = 0.03
"""Peak platform speed of a commanded move [m/s] (min-jerk: duration = 1.875 d / speed)."""


def transform(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, pos
    return out


def inverse(t: np.ndarray) -> np.ndarray:
    return transform(t[:3, :3].T, -t[:3, :3].T @ t[:3, 3])


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking unit vector a onto unit vector b."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    axis, c = np.cross(a, b), float(a @ b)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]) / s
    angle = np.arctan2(s, c)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def platform_T_plate(model: mujoco.MjModel) -> np.ndarray:
    """The fixture: plate frame in the platform-centre frame, from the cell's design (both are
    fixed in the platform body, so this is a constant of the model, not a state)."""
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    site = model.site(names.STEWART + "platform_centre").id
    plate = model.body(names.PLATE + "baseplate").id
    w_T_site = transform(data.site_xmat[site].reshape(3, 3), data.site_xpos[site])
    w_T_plate = transform(data.xmat[plate].reshape(3, 3), data.xpos[plate])
    return inverse(w_T_site) @ w_T_plate


@dataclass
class PlateCommander:
    """The platform's model and its command state: poses in, leg strokes out, ramped."""

    servo: StewartServo
    dl: np.ndarray
    """Leg-length offsets the model believes [m] (0 for the nominal model)."""
    platform_T_plate: np.ndarray
    commanded: np.ndarray
    """Platform pose in the Stewart base frame the model believes it has commanded."""
    base_T_stewart: np.ndarray | None = None
    """Stewart base frame in the arm base frame, from the registration."""
    _ramp: tuple[np.ndarray, np.ndarray, float, float] | None = field(default=None, repr=False)

    @classmethod
    def create(cls, model: mujoco.MjModel, data: mujoco.MjData, cfg: StewartConfig,
               believed: np.ndarray | None) -> PlateCommander:
        """`believed`: the (6, 7) joint errors the model uses (identified ones), or None.

        The pose in force is where the model puts the legs' current commands (the cell starts
        on the nominal home strokes): a calibrated model places them up to millimetres from
        the nominal home, and assuming home would offset every later move by that much."""
        geometry, dl = built_geometry(dataclasses.replace(cfg, joint_errors=believed))
        servo = StewartServo.from_model(model, geometry, names.STEWART, match_tol=2 * MAX_JOINT_ERROR)
        in_force = data.ctrl[list(servo.actuator_ids)]
        pos, rot, _ = forward_kinematics(geometry, in_force + dl, np.asarray(cfg.home_pos, float))
        return cls(servo, dl, platform_T_plate(model), transform(rot, pos))

    @property
    def geometry(self) -> StewartGeometry:
        return self.servo.geometry

    def register(self, plate: PlateMeasurement) -> None:
        """Stewart base in the camera (arm base) frame from one plate measurement, taken with
        the platform settled at the commanded pose."""
        base_T_plate = transform(plate.rotation, plate.origin)
        self.base_T_stewart = base_T_plate @ inverse(self.platform_T_plate) @ inverse(self.commanded)

    def plate_pose(self) -> np.ndarray:
        """Where the model says the plate is now, in the arm base frame."""
        assert self.base_T_stewart is not None, "register() first"
        return self.base_T_stewart @ self.commanded @ self.platform_T_plate

    def goal_for(self, hole_in_plate: np.ndarray, axis_in_plate: np.ndarray, entry: np.ndarray,
                 axis: np.ndarray) -> np.ndarray:
        """Platform command putting the hole entry (plate frame) at `entry` (base frame) with the
        hole axis along `axis`, turning the plate as little as possible."""
        current = self.plate_pose()
        rot = rotation_between(current[:3, :3] @ axis_in_plate, axis) @ current[:3, :3]
        base_T_plate = transform(rot, entry - rot @ hole_in_plate)
        return inverse(self.base_T_stewart) @ base_T_plate @ inverse(self.platform_T_plate)

    def strokes(self, pose: np.ndarray) -> np.ndarray:
        """Leg commands for a platform pose; LimitError names the leg and the limit."""
        return require_pose(self.geometry, pose[:3, 3], pose[:3, :3]) - self.dl

    def move_to(self, data: mujoco.MjData, goal: np.ndarray, now: float, speed: float = RAMP_SPEED) -> float:
        """Start a min-jerk ramp from the commanded pose to `goal` at peak `speed` [m/s];
        returns its duration [s]. The goal's limits are checked now, before anything moves."""
        self.strokes(goal)
        start = self.commanded.copy()
        dist = float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
        duration = max(MIN_RAMP_S, 1.875 * dist / speed)
        self._ramp = (start, goal, now, duration)
        self.update(data, now)
        return duration

    def update(self, data: mujoco.MjData, now: float) -> None:
        """Advance the ramp (call every control period)."""
        if self._ramp is None:
            return
        start, goal, t0, duration = self._ramp
        tau = min(1.0, (now - t0) / duration)
        s = 10 * tau**3 - 15 * tau**4 + 6 * tau**5
        pose = transform(_slerp(start[:3, :3], goal[:3, :3], s), start[:3, 3] + s * (goal[:3, 3] - start[:3, 3]))
        self._command(data, pose)
        if tau >= 1.0:
            self._ramp = None

    def nudge(self, data: mujoco.MjData, goal: np.ndarray) -> None:
        """Command `goal` at once, ending any ramp: for corrections of a few micrometres, which
        the leg servos follow within milliseconds."""
        self._ramp = None
        self._command(data, goal)

    def _command(self, data: mujoco.MjData, pose: np.ndarray) -> None:
        self.servo.command_strokes(data, self.strokes(pose))
        self.commanded = pose

    def reset_to(self, commanded: np.ndarray) -> None:
        """Forget any ramp and take `commanded` as the pose in force (after a state restore)."""
        self.commanded, self._ramp = commanded.copy(), None

    @property
    def moving(self) -> bool:
        return self._ramp is not None


def _slerp(r0: np.ndarray, r1: np.ndarray, s: float) -> np.ndarray:
    return so3_exp(s * orientation_error(r0, r1)) @ r0
