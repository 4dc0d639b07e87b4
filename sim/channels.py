"""The recording schema's channel and column names (docs/recording.md): the one place every
writer and reader of a recording takes them from. libfranka's names where one exists."""

from __future__ import annotations

import math
import re

from serpar.errors import ConfigError


def numbered(prefix: str, count: int) -> tuple[str, ...]:
    """prefix1 .. prefix<count>."""
    return tuple(f"{prefix}{i}" for i in range(1, count + 1))


TIME = "time"
PHASE = "phase"
USER_PREFIX = "x_"
"""User channels: any name starting with x_."""

# the arm (libfranka RobotState): the constants name the Panda's 7 joints; the families
# (ARM_FAMILIES) take any arm of up to MAX_ARM_JOINTS joints, q1..q16 and so on.
MAX_ARM_JOINTS = 16
Q = numbered("q", 7)
DQ = numbered("dq", 7)
TAU_J = numbered("tau_J", 7)
"""Measured link-side joint torques [N m]."""
TAU_J_D = numbered("tau_J_d", 7)
"""Commanded joint torques [N m]."""
TAU_DRIVE = numbered("tau_drive", 7)
"""Drive torque on the joint side [N m], from the motor current (x torque constant) or the
drive's motor torque through the gear ratio: what the motor puts in, friction inside the drive
included. tau_J is the link-side sensor after the gearbox, blind to that friction."""
ARM_FAMILIES = ("q", "dq", "tau_J", "tau_J_d", "tau_drive")
"""Per-joint channel families: <prefix><k> for joint k = 1..MAX_ARM_JOINTS."""
F_EXT = numbered("O_F_ext_hat_K", 6)
"""Estimated external wrench at the TCP, base frame [N, N m]."""
M_LOAD = "m_load"
"""Mass of the load the controller was told the hand carries (libfranka setLoad) [kg]."""
F_X_CLOAD = numbered("F_x_Cload", 3)
"""That load's centre of mass in the flange frame [m] (libfranka F_x_Cload)."""
TCP_POSITION = ("O_T_EE_x", "O_T_EE_y", "O_T_EE_z")
TCP_QUAT = ("O_T_EE_qw", "O_T_EE_qx", "O_T_EE_qy", "O_T_EE_qz")

# the Stewart platform
LEG_CMD = numbered("leg_cmd", 6)
"""Commanded leg lengths l_min + stroke [m]."""
LEG = numbered("leg", 6)
"""Measured leg lengths [m]."""
PLATFORM_POSITION = ("platform_x", "platform_y", "platform_z")
PLATFORM_QUAT = ("platform_qw", "platform_qx", "platform_qy", "platform_qz")
"""Platform pose in the Stewart base frame [m, unit quaternion w x y z]."""

# the cell
GRIPPER_WIDTH = "gripper_width"
CONTACT_FORCE = ("contact_force_x", "contact_force_y", "contact_force_z")

KNOWN = (TIME, PHASE, *Q, *DQ, *TAU_J, *TAU_J_D, *TAU_DRIVE, *F_EXT, M_LOAD, *F_X_CLOAD,
         *TCP_POSITION, *TCP_QUAT, *LEG_CMD, *LEG, *PLATFORM_POSITION, *PLATFORM_QUAT,
         GRIPPER_WIDTH, *CONTACT_FORCE)
"""The named channels (the arm's for the Panda's 7 joints; is_channel takes joints 1..16)."""
_J = MAX_ARM_JOINTS
KNOWN_HELP = (f"time, phase, q1..{_J}, dq1..{_J}, tau_J1..{_J}, tau_J_d1..{_J}, tau_drive1..{_J} "
              "(an arm's joints 1..16), O_F_ext_hat_K1..6, m_load, F_x_Cload1..3, "
              "O_T_EE_x/y/z/qw/qx/qy/qz, leg_cmd1..6, leg1..6, platform_x/y/z/qw/qx/qy/qz, "
              "gripper_width, contact_force_x/y/z, x_<anything>")

# the measurements table (static calibration sets)
MEASUREMENT_KINDS = ("position", "point")
MEASUREMENT_SETS = ("train", "verify")
APPROACH = numbered("approach", 7)
"""Joint angles the arm came from before settling into a measured pose [rad]."""
MEASUREMENT_REQUIRED = (*Q, "kind")
MEASUREMENT_OPTIONAL = ("x", "y", "z", "socket", "time", "set", "placement", *APPROACH)
MEASUREMENT_HELP = "q1..q7, kind, x/y/z (position), socket (point), time, approach1..7, set, placement"


_TAU_MAX = (500.0, "N m")
_LENGTH_MAX = (5.0, "m")
_QUAT_MAX = (1.01, "(unit quaternion)")
PLAUSIBLE_MAX: dict[str, tuple[float, str]] = {
    **dict.fromkeys(Q, (2 * math.pi + 0.1, "rad")), **dict.fromkeys(DQ, (20.0, "rad/s")),
    **dict.fromkeys(TAU_J, _TAU_MAX), **dict.fromkeys(TAU_J_D, _TAU_MAX),
    **dict.fromkeys(TAU_DRIVE, _TAU_MAX),
    **dict.fromkeys(F_EXT, (1e4, "N or N m")), M_LOAD: (50.0, "kg"), **dict.fromkeys(F_X_CLOAD, (2.0, "m")),
    **dict.fromkeys(TCP_POSITION, _LENGTH_MAX),
    **dict.fromkeys(TCP_QUAT, _QUAT_MAX), **dict.fromkeys(LEG_CMD, (2.0, "m")),
    **dict.fromkeys(LEG, (2.0, "m")), **dict.fromkeys(PLATFORM_POSITION, _LENGTH_MAX),
    **dict.fromkeys(PLATFORM_QUAT, _QUAT_MAX), GRIPPER_WIDTH: (1.0, "m"),
    **dict.fromkeys(CONTACT_FORCE, (1e5, "N")), **dict.fromkeys(("x", "y", "z"), _LENGTH_MAX),
}
"""Largest magnitude a robot can report per channel (and measurement column) in SI units:
beyond it the unit is wrong (degrees, millimetres) or the value corrupt."""


_FAMILY_MAX = {"q": PLAUSIBLE_MAX[Q[0]], "dq": PLAUSIBLE_MAX[DQ[0]], "tau_J": _TAU_MAX,
               "tau_J_d": _TAU_MAX, "tau_drive": _TAU_MAX}


def arm_family(prefix: str, n: int) -> tuple[str, ...]:
    """The channels of one arm family for an arm of ``n`` joints: ``arm_family("q", 6)`` is
    q1..q6."""
    if prefix not in ARM_FAMILIES:
        raise ConfigError(f"arm channel family {prefix!r}; valid: {', '.join(ARM_FAMILIES)}")
    if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_ARM_JOINTS:
        raise ConfigError(f"an arm of {n!r} joints; valid: 1..{MAX_ARM_JOINTS}")
    return numbered(prefix, n)


def arm_joint(name: str) -> tuple[str, int] | None:
    """(family, joint k) of an arm channel (``tau_J_d12`` -> ("tau_J_d", 12)), else None."""
    m = _ARM_RE.fullmatch(name)
    if m is None or int(m[2]) > MAX_ARM_JOINTS:
        return None
    return m[1], int(m[2])


def plausible_max(name: str) -> tuple[float, str] | None:
    """(largest plausible |value|, unit) of a channel, None where the schema sets no bound."""
    bound = PLAUSIBLE_MAX.get(name)
    if bound is None and (arm := arm_joint(name)) is not None:
        bound = _FAMILY_MAX[arm[0]]
    return bound


def is_channel(name: str) -> bool:
    """A signals column the schema knows (an arm channel of joint 1..16, or a user channel)."""
    return (name in _KNOWN_SET or arm_joint(name) is not None
            or _USER_RE.fullmatch(name) is not None)


_KNOWN_SET = frozenset(KNOWN)
_USER_RE = re.compile(re.escape(USER_PREFIX) + r"[A-Za-z0-9_]+")
# longest prefix first: tau_J_d12 is tau_J_d's joint 12, not tau_J's
_ARM_RE = re.compile(r"(tau_drive|tau_J_d|tau_J|dq|q)([1-9][0-9]?)")
