"""The hand's servo, with the Franka Hand's two commands: ``move(width)`` and
``grasp(width, speed, force)``.

A grasp closes the jaw at a bounded speed and squeezes once the jaw is blocked, as libfranka's
grasp does. Squeezing from the open hand at once (the force alone driving the fingers) threw
them at the part at up to 0.9 m/s per finger: a part off-centre between the pads was struck by
one pad, knocked across its tray pocket at ~1 m/s and tumbled into the pocket's wall at
~500 rad/s, and the episode filed a blown-up grasp (cell 26 of docs/sim2real.md; the serial-arm
ablation on MuJoCo 4.0.1). A real hand never closes that fast.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.errors import ConfigError
from serpar.sim import names
from serpar.sim.arm import FINGER_JOINT_NAMES, GRIP_ACTUATOR, GRIP_FORCE_MAX

GRASP_SPEED = 0.04
"""Closing speed of the jaw width during a grasp [m/s]: frankx's default for the Franka Hand,
whose maximum is 0.1 m/s (frankx ``Gripper::max_speed``; libfranka's ``grasp`` takes it as an
argument). Closing the cell's 1.5 mm margin takes ~40 ms."""
SQUEEZE_RISE = 0.02
"""Time the squeeze takes to rise to its full force once the jaw is blocked [s]. A step
accelerates the ~20 g finger at ~1000 m/s^2 where the jaw was blocked by a part pushed against
its pocket's wall rather than by both pads (0.29 m/s within a millisecond, and the part blew
up); over 20 ms the part straightens between the pads first."""
BLOCKED_LAG = 3e-4
"""Jaw width above its closing reference that means the pads are blocked by the part [m]:
above the lag of the free fingers' tracking (kd * speed / kp = 0.2 mm at GRASP_SPEED)."""


@dataclass
class GripperServo:
    """A PD on the jaw width (``open_to``, and a grasp while the jaw closes on its speed-limited
    reference), then a squeeze per pad [N] rising over SQUEEZE_RISE once the jaw is blocked."""

    actuator: int
    finger_qpos: np.ndarray
    finger_dof: np.ndarray
    period: float
    """Control period [s]: how far the grasp's reference moves each update."""
    kp: float = 4000.0
    """[N/m] on the jaw width: 1 mm error -> 4 N."""
    kd: float = 20.0
    width_target: float | None = 0.0
    """The width the PD holds (None: the grasp's reference decides)."""
    squeeze: float = 0.0
    closing_speed: float = GRASP_SPEED
    reference: float | None = None
    """The grasp's closing reference width [m] (None before its first update)."""
    blocked: bool = False
    """The grasp has met the part: the squeeze alone acts."""
    force: float = 0.0
    """The squeeze commanded now [N per pad]: it rises to ``squeeze`` over SQUEEZE_RISE once
    the jaw is blocked."""

    @classmethod
    def from_model(cls, model: mujoco.MjModel, period: float) -> GripperServo:
        joints = [model.joint(names.ARM + j) for j in FINGER_JOINT_NAMES]
        return cls(model.actuator(names.ARM + GRIP_ACTUATOR).id,
                   np.array([j.qposadr[0] for j in joints]), np.array([j.dofadr[0] for j in joints]),
                   period)

    def open_to(self, width: float) -> None:
        self.width_target, self.squeeze, self.reference, self.blocked = width, 0.0, None, False

    def grasp(self, squeeze: float, speed: float = GRASP_SPEED) -> None:
        """Close at ``speed`` [m/s of jaw width] until the pads are blocked, then squeeze
        ``squeeze`` [N per pad]."""
        if not 0 < squeeze <= GRIP_FORCE_MAX:
            raise ConfigError(f"grasp squeeze {squeeze} N: valid (0, {GRIP_FORCE_MAX}] N per pad")
        if not 0 < speed <= 0.1:
            raise ConfigError(f"grasp speed {speed} m/s: valid (0, 0.1] m/s (the Franka Hand's maximum)")
        self.width_target, self.squeeze, self.closing_speed = None, squeeze, speed
        self.reference, self.blocked = None, False

    def command(self) -> tuple:
        """What the servo is doing (for a snapshot): restore it with :meth:`resume`."""
        return (self.width_target, self.squeeze, self.closing_speed, self.reference, self.blocked,
                self.force)

    def resume(self, command: tuple) -> None:
        (self.width_target, self.squeeze, self.closing_speed, self.reference, self.blocked,
         self.force) = command

    def width(self, data: mujoco.MjData) -> float:
        return float(data.qpos[self.finger_qpos].sum())

    def _pd(self, data: mujoco.MjData, target: float) -> float:
        # positive ctrl closes the jaw
        return self.kp * (self.width(data) - target) + self.kd * float(data.qvel[self.finger_dof].sum())

    def update(self, data: mujoco.MjData) -> None:
        if self.width_target is not None:
            force = self._pd(data, self.width_target)
        else:
            force = self._grasp(self.width(data), data)
        data.ctrl[self.actuator] = float(np.clip(force, -GRIP_FORCE_MAX, GRIP_FORCE_MAX))

    def _grasp(self, width: float, data: mujoco.MjData) -> float:
        if self.reference is None:
            self.reference = width
        if not self.blocked:
            self.reference = max(0.0, self.reference - self.closing_speed * self.period)
            pd = self._pd(data, self.reference)
            if width - self.reference <= BLOCKED_LAG:
                return min(pd, self.squeeze)
            self.blocked, self.force = True, float(np.clip(pd, 0.0, self.squeeze))
        self.force = min(self.squeeze, self.force + self.squeeze * self.period / SQUEEZE_RISE)
        return self.force
