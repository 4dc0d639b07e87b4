"""What a "real" arm of the arm-dynamics twin has beyond its nominal MjModel: the sensors' noise
(:class:`SensorNoise`) and the sensor and drive effects that act on the signals
(:class:`Reality`), for an arm of any number of joints (sim/plants/moving_arm.py runs them).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.arm import N_JOINTS
from serpar.sim.plants.drive_friction import (
    STRIBECK_SMOOTHING,
    sigmoid_friction_torque,
    stribeck_fall_torque,
)

Vec = NDArray[np.float64]

_VECTORS = (("torque_gain", -np.inf, np.inf, 0.0), ("torque_bias", -np.inf, np.inf, 0.0),
            ("encoder_offset", -np.inf, np.inf, 0.0), ("encoder_scale", -0.05, 0.05, 0.0),
            ("stribeck_excess", 0.0, 5.0, 0.0), ("stribeck_speed", 1e-3, 1.0, 0.05),
            ("link_side_viscous", 0.0, 5.0, 0.0))
"""Per-joint fields of :class:`Reality`: name, valid range, the value where unset."""


@dataclass(frozen=True)
class SensorNoise:
    torque_std: float = 0.02
    """White noise of each tau_J sample [N m] (Panda order)."""
    torque_bias_std: float = 0.05
    """Start-up offset of each torque sensor [N m] (drawn; the diagnosis tares it)."""
    encoder_counts_per_rev: int = 2**20
    velocity_std: float = 1e-3
    actuation_std: float = 0.02
    """Torque ripple of the drive: white, per control period, about the command [N m]."""

    def __post_init__(self) -> None:
        for name in ("torque_std", "torque_bias_std", "velocity_std", "actuation_std"):
            if not getattr(self, name) >= 0:
                raise ConfigError(f"SensorNoise.{name}={getattr(self, name)} must be >= 0")
        if self.encoder_counts_per_rev < 0:
            raise ConfigError("SensorNoise.encoder_counts_per_rev must be >= 0")

    @property
    def encoder_sigma(self) -> float:
        """Quantisation noise of one encoder reading: step / sqrt(12) [rad]."""
        return (2 * np.pi / self.encoder_counts_per_rev / np.sqrt(12)
                if self.encoder_counts_per_rev else 0.0)


@dataclass(frozen=True)
class Coupling:
    """A coupled drive (a coupled wrist, as the Staubli TX40's joints 5 and 6): the motor of
    joint ``motor`` also turns joint ``joint``, so it spins with their sum. Beyond each joint's
    own rotor inertia and viscous friction (its armature and damping), each joint's drive
    carries the motor's in the *other* joint's motion: Iam ddq_other + fvm dq_other (0-based
    joints; FIGAROH's structure, as the diagnosis' coupled_pair). The motor's dry friction,
    fsm sign(dq_joint + dq_motor) on both, is a fixed tendon's ``frictionloss`` in the plant's
    spec (MuJoCo's implicit friction constraint: it sticks when the motor stops)."""

    joint: int
    motor: int
    inertia: float
    """Iam [kg m^2]."""
    viscous: float
    """fvm [N m s/rad]."""

    def check(self, n: int) -> None:
        if not (0 <= self.joint < n and 0 <= self.motor < n and self.joint != self.motor):
            raise ConfigError(f"Reality.coupling joints {self.joint}, {self.motor}: two different "
                              f"joint indices in 0..{n - 1}")
        for name, hi in (("inertia", 1.0), ("viscous", 5.0)):
            v = getattr(self, name)
            if not (np.isfinite(v) and 0.0 <= v <= hi):
                raise ConfigError(f"Reality.coupling {name}={v} outside 0..{hi:g}")


@dataclass(frozen=True)
class Reality:
    """What the real arm has beyond the nominal model, outside its MjModel (sensors, drive).
    Per-joint fields left unset are the neutral value for ``n`` joints (the Panda's 7 unless
    given)."""

    torque_gain: Vec | None = None
    """Relative gain error of each torque sensor (0.02 = reads 2 % high)."""
    torque_bias: Vec | None = None
    """Extra offset of each torque sensor [N m], on top of the start-up draw."""
    encoder_offset: Vec | None = None
    """Measured minus true joint angle [rad]."""
    encoder_scale: Vec | None = None
    """Relative scale error of each encoder about its zero: it reads q (1 + s) + offset."""
    delay: float = 0.0
    """Actuation latency: a command reaches the joint this much later [s]."""
    sensor_lag: float = 0.0
    """The torque sensors' readings belong to this much earlier than the encoders' [s]
    (a whole number of physics substeps)."""
    stribeck_excess: Vec | None = None
    """Static minus Coulomb friction of each drive, Fs - Fc [N m]: at joint speed v the drive
    loses (Fs - Fc) exp(-(v / vs)^2) more, against the motion (the Coulomb and viscous parts
    are the plant's MuJoCo frictionloss and damping)."""
    stribeck_speed: Vec | None = None
    """Stribeck velocity vs of each drive [rad/s] (unset: 0.05)."""
    ripple: tuple[tuple[int, float, float, float], ...] = ()
    """Position-periodic transmission ripple, one (joint index 0..n-1, amplitude [N m], period
    [rad], phase [rad]) per rippling joint: the drive adds A sin(2 pi q / period + phase)."""
    link_side_friction: bool = False
    """The joints' dry friction (MuJoCo's frictionloss) acts between the torque sensor and the
    link (output bearings, seals), so the sensors read it: the drive must pass it through."""
    link_side_viscous: Vec | None = None
    """The part of each joint's damping [N m s/rad] that acts on the link side of the sensor."""
    coupling: Coupling | None = None
    """A coupled drive's extra torque (None: every joint has its own motor only)."""
    sigmoid_phi: Vec | None = None
    """Drive friction in the published Panda form (3 x n: phi1 [N m], phi2 [s/rad], phi3 [rad/s]
    per joint; sim/plants/drive_friction.py): the drive loses
    phi1 (sigma(phi2 (dq + phi3)) - sigma(phi2 phi3)). None: none."""
    stribeck_width: Vec | None = None
    """Per-joint width of the smoothed signs [rad/s] (None: :data:`STRIBECK_SMOOTHING` on every
    joint); a light joint needs a wider one to stay stable (sim/plants/moving_arm.py)."""
    n: int = N_JOINTS
    """Joints of the arm."""

    def __post_init__(self) -> None:
        n = self.n
        for name, lo, hi, unset in _VECTORS:
            raw = getattr(self, name)
            v = np.full(n, unset) if raw is None else np.asarray(raw, float)
            if v.shape != (n,) or not np.all(np.isfinite(v)):
                raise ConfigError(f"Reality.{name} needs {n} finite values")
            if np.any(v < lo) or np.any(v > hi):
                raise ConfigError(f"Reality.{name}={v.tolist()} outside {lo:g}..{hi:g}")
            object.__setattr__(self, name, v)
        if self.stribeck_width is not None:
            w = np.asarray(self.stribeck_width, float)
            if w.shape != (n,) or not np.all((w >= STRIBECK_SMOOTHING) & (w <= 1.0)):
                raise ConfigError(f"Reality.stribeck_width needs {n} values in "
                                  f"{STRIBECK_SMOOTHING:g}..1 rad/s")
            object.__setattr__(self, "stribeck_width", w)
        if self.sigmoid_phi is not None:
            phi = np.asarray(self.sigmoid_phi, float)
            if (phi.shape != (3, n) or not np.all(np.isfinite(phi)) or np.any(phi[0] < 0)
                    or np.any(phi[1] <= 0)):
                raise ConfigError(f"Reality.sigmoid_phi needs 3 x {n} finite values, phi1 >= 0 "
                                  "and phi2 > 0")
            object.__setattr__(self, "sigmoid_phi", phi)
        if not 0.0 <= self.delay <= 0.02:
            raise ConfigError(f"Reality.delay={self.delay} s outside 0..0.02 s")
        if not 0.0 <= self.sensor_lag <= 0.005:
            raise ConfigError(f"Reality.sensor_lag={self.sensor_lag} s outside 0..0.005 s")
        object.__setattr__(self, "ripple", tuple(_ripple_entry(r, n) for r in self.ripple))
        joints = [r[0] for r in self.ripple]
        if len(set(joints)) != len(joints):
            raise ConfigError(f"Reality.ripple names a joint twice: {joints}")
        if self.coupling is not None:
            self.coupling.check(n)

    def encoder_reading(self, q: Vec) -> Vec:
        """What the encoders read at the true angles q, before quantisation [rad]."""
        return q * (1.0 + self.encoder_scale) + self.encoder_offset

    def drive_torque(self) -> Callable[..., Vec] | None:
        """The drive's torque beyond its command at true (q, dq) and the last step's
        acceleration ddq [N m], or None without one (the simulation then skips it): Stribeck
        friction, the published sigmoid friction, position ripple, a coupled motor."""
        stribeck = bool(np.any(self.stribeck_excess > 0))
        sigmoid = self.sigmoid_phi
        if not stribeck and not self.ripple and self.coupling is None and sigmoid is None:
            return None
        excess, speed = self.stribeck_excess, self.stribeck_speed
        width = np.full(self.n, STRIBECK_SMOOTHING) if self.stribeck_width is None else self.stribeck_width
        joint = np.array([r[0] for r in self.ripple], int)
        amp, period, phase = (np.array([r[i] for r in self.ripple], float) for i in (1, 2, 3))
        wavenumber = 2 * np.pi / period if len(period) else period
        n, c = self.n, self.coupling

        def torque(q: Vec, dq: Vec, ddq: Vec | None = None) -> Vec:
            # called at every 0.1 ms substep: a few whole-vector ufuncs (~2.5 us), no loops.
            # tanh instead of sign: continuous through v = 0, where MuJoCo's frictionloss
            # constraint holds the joint; 1 mm/s keeps h * slope / inertia < 1 at the twin's
            # Fs - Fc (<= 0.8 N m on wrist joints of >= 0.1 kg m^2): explicit and still stable
            out = -stribeck_fall_torque(dq, excess, speed, width) if stribeck else np.zeros(n)
            if sigmoid is not None:  # explicit: its slope phi1 phi2 / 4 is a few N m s/rad
                out -= sigmoid_friction_torque(dq, *sigmoid)
            if len(joint):
                out[joint] += amp * np.sin(wavenumber * q[joint] + phase)
            if c is not None:
                # the coupled motor's rotor and viscous friction in the other joint's motion
                # (the drive loses them; the link-side sensor sees them only through the
                # motion). The acceleration is the last substep's: explicit, stable while
                # Iam sqrt(M^-1_jj M^-1_mm) << 1 (the twin sizes Iam so)
                a, m = c.joint, c.motor
                acc = (0.0, 0.0) if ddq is None else (ddq[a], ddq[m])
                out[a] -= c.inertia * acc[1] + c.viscous * dq[m]
                out[m] -= c.inertia * acc[0] + c.viscous * dq[a]
            return out

        return torque


def _ripple_entry(r: tuple[int, float, float, float], n: int) -> tuple[int, float, float, float]:
    try:
        values = np.asarray(r, float)
    except (TypeError, ValueError):
        values = np.empty(0)
    if values.shape != (4,) or not np.all(np.isfinite(values)):
        raise ConfigError(f"Reality.ripple entry {r} needs 4 finite values "
                          "(joint index, amplitude, period, phase)")
    j, amp, period, phase = r
    if int(j) != j or not 0 <= j < n:
        raise ConfigError(f"Reality.ripple joint index {j} outside 0..{n - 1}")
    if not 0.0 <= amp <= 5.0:
        raise ConfigError(f"Reality.ripple amplitude {amp} N m outside 0..5 N m")
    if not 0.01 <= period <= 2 * np.pi:
        raise ConfigError(f"Reality.ripple period {period} rad outside 0.01..2 pi rad")
    return int(j), float(amp), float(period), float(phase)
