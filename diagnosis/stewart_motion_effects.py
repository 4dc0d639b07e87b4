"""A MOVING Stewart platform recording for the diagnosis: its samples, the nominal servo's
tracking of the commands, and the latency candidates.

Signals as the rest-hold family's (diagnosis/stewart_data.py): ``leg_cmd1..6``,
``leg1..6`` (leg lengths l_min + stroke [m]), ``platform_x/y/z``, ``platform_qw/qx/qy/qz``
(Stewart base frame), ``meta.noise_sigma`` of the platform channels and, required here, of the
legs (the tracking residual is judged against the encoders' noise). Every sample is used.

The nominal servo: sim/stewart.py's PID leg servos are not stiff enough for "measured =
commanded" in motion (their damping acts on the leg's velocity, so an accelerating leg lags
by ~kv/ki * acceleration, up to a millimetre), and the lag depends on the platform's coupled
dynamics and loads. So the nominal tracking is MuJoCo's own: the nominal platform (the
recording's payload on sim/stewart.py's default StewartConfig) is brought to rest at the first
command and driven by the recorded commands, each held from its sample to the next (the
controller's zero-order hold), and its slides are kept at every physics step. A latency tau
of the whole actuation chain then shows as that response shifted by tau (exact for a
time-invariant plant starting at rest); np.interp on the 0.1 ms grid evaluates it.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.family import Effect
from serpar.diagnosis.stewart_data import (
    CMDS,
    CONFIG_KEYS,
    LEGS,
    POSE,
    _column,
    _platform,
    _sigma,
    _stewart_meta,
    require_channels,
)
from serpar.errors import IdentificationError
from serpar.kinematics.rotations import quat_to_rot
from serpar.sim.plants.stewart_platform import PlatformPlant, Reality
from serpar.sim.recording import Recording
from serpar.sim.stewart import StewartConfig
from serpar.sim.stewart_statics import Load

Vec = NDArray[np.float64]
SERVO_LAG, MOCAP_LATENCY = "leg_servo_lag", "mocap_latency"
SERVO_BOUNDS_S = (-0.02, 0.05)
MOCAP_BOUNDS_S = (-0.05, 0.1)
"""Either sign admitted: an absent latency's estimate scatters about zero."""
MIN_SAMPLES = 200
MOVING_SHARE = 0.5
"""A Stewart recording whose leg commands change at more than this share of its samples is
a motion recording (rest-hold campaigns change them once per hold)."""
CMD_TOL_M = 1e-9


@dataclass(frozen=True)
class MotionSamples:
    """Every sample of a moving-platform recording (time from its first sample)."""

    time: Vec
    cmd: Vec
    """(n, 6) commanded leg lengths [m]."""
    legs: Vec
    pos: Vec
    rot: Vec
    sigma_pos: float
    sigma_rot: float
    sigma_leg: float
    config: dict[str, object]
    load: Load

    @property
    def n(self) -> int:
        return len(self.time)


def moving_share(rec: Recording) -> float:
    """Share of samples whose leg command differs from the sample before (0 without the
    leg_cmd channels: the rest-hold family then names what is missing)."""
    cols = set(rec.signals.column_names)
    if not set(CMDS) <= cols or rec.signals.num_rows < 2:
        return 0.0
    cmd = np.column_stack([np.asarray(rec.signals.column(c).to_numpy(zero_copy_only=False),
                                      float) for c in CMDS])
    return float(np.mean(np.any(np.abs(np.diff(cmd, axis=0)) > CMD_TOL_M, axis=1)))


def read_motion(rec: Recording) -> MotionSamples:
    """The samples of a moving-platform recording; IdentificationError names what is wrong."""

    require_channels(rec, "a Stewart motion recording")
    cfg, load = _platform(rec)
    t = _column(rec, "time")
    if len(t) < MIN_SAMPLES or np.any(np.diff(t) <= 0):
        raise IdentificationError(f"a Stewart motion recording needs >= {MIN_SAMPLES} samples "
                                  f"at increasing times, got {len(t)}")
    cmd = np.column_stack([_column(rec, c) for c in CMDS])
    legs = np.column_stack([_column(rec, c) for c in LEGS])
    lo, hi = cfg.l_min - 5e-3, cfg.l_min + cfg.stroke + 5e-3
    for name, x in zip(CMDS + LEGS, np.hstack([cmd, legs]).T):
        if x.min() < lo or x.max() > hi:
            raise IdentificationError(
                f"{name} ranges {x.min():.6g}..{x.max():.6g}, outside the nominal platform's leg "
                f"lengths {cfg.l_min:.4f}..{cfg.l_min + cfg.stroke:.4f} m (+-5 mm)")
    pos = np.column_stack([_column(rec, c) for c in POSE[:3]])
    quat = np.column_stack([_column(rec, c) for c in POSE[3:]])
    norm = np.linalg.norm(quat, axis=1)
    if np.max(np.abs(norm - 1.0)) > 1e-3:
        k = int(np.argmax(np.abs(norm - 1.0)))
        raise IdentificationError(f"platform_qw/qx/qy/qz is not a unit quaternion at row {k} "
                                  f"(norm {norm[k]:.6g})")
    if np.max(np.linalg.norm(pos - cfg.home_pos, axis=1)) > 0.2:
        raise IdentificationError("platform_x/y/z reach over 0.2 m from the home pose: not "
                                  "metres in the Stewart base frame")
    sigma_leg = _sigma(rec, LEGS, True)
    return MotionSamples(t - t[0], cmd, legs, pos, quat_to_rot(quat / norm[:, None]),
                         _sigma(rec, POSE[:3], True), 2.0 * _sigma(rec, POSE[4:], True),
                         sigma_leg, {k: getattr(cfg, k) for k in CONFIG_KEYS}, load)


@dataclass(frozen=True)
class NominalTrack:
    """The nominal platform's slides [m] and their rates [m/s] at every physics step."""

    time: Vec
    slides: Vec
    rates: Vec

    def at(self, t: Vec) -> tuple[Vec, Vec]:
        """Slides and rates (n, 6) at times t (held at the ends)."""
        s = np.column_stack([np.interp(t, self.time, self.slides[:, i]) for i in range(6)])
        v = np.column_stack([np.interp(t, self.time, self.rates[:, i]) for i in range(6)])
        return s, v


def nominal_track(data: MotionSamples, rec: Recording) -> NominalTrack:
    """MuJoCo's nominal platform at rest at the first command, then driven by the recorded
    commands held from sample to sample (see the module docstring)."""

    given = _stewart_meta(rec)
    default = StewartConfig()
    odd = [k for k in CONFIG_KEYS if k in given and given[k] != getattr(default, k)]
    if odd:
        raise IdentificationError(f"the motion diagnosis simulates sim/stewart.py's default "
                                  f"platform; meta.model['stewart'] changes {', '.join(odd)}")
    load = data.load
    plant = PlatformPlant(Reality(payload_kg=load.payload_kg, payload_com_m=load.payload_com))
    m, d = plant.model, plant.data
    strokes = data.cmd - default.l_min
    geom = default.geometry()
    plant.settle(strokes[0], 0.0, (np.asarray(geom.home_pos), np.eye(3)))
    legs = [int(mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"leg{i}")) for i in range(1, 7)]
    qadr, vadr = m.jnt_qposadr[legs], m.jnt_dofadr[legs]
    dt = m.opt.timestep
    steps = np.maximum(np.round(np.diff(data.time) / dt).astype(int), 1)
    total = int(steps.sum()) + 1
    slides, rates = np.zeros((total, 6)), np.zeros((total, 6))
    slides[0], rates[0] = d.qpos[qadr], d.qvel[vadr]
    k = 1
    for i, n in enumerate(steps):
        d.ctrl[:] = strokes[i]
        for _ in range(n):
            mujoco.mj_step(m, d)
            slides[k], rates[k] = d.qpos[qadr], d.qvel[vadr]
            k += 1
    if d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
        raise IdentificationError("the nominal platform went unstable under the recorded "
                                  "commands (MuJoCo bad qacc): not commands of this platform")
    return NominalTrack(np.arange(total) * dt, slides, rates)


def latency_effects() -> tuple[Effect, ...]:
    """The two latencies the rest-hold family can never see."""
    return (
        Effect(SERVO_LAG, "actuation latency (leg servos act on late commands)", ("tau_servo",),
               ("s",), np.zeros(1), np.array([SERVO_BOUNDS_S[0]]), np.array([SERVO_BOUNDS_S[1]])),
        Effect(MOCAP_LATENCY, "sensing latency (platform pose measured late against the leg "
               "encoders)", ("tau_mocap",), ("s",), np.zeros(1), np.array([MOCAP_BOUNDS_S[0]]),
               np.array([MOCAP_BOUNDS_S[1]])),
    )
