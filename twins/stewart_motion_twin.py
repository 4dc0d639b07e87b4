"""Concealed-effect twins of a MOVING Stewart platform (issue 7, latency candidates): the "real"
platform is MuJoCo's (sim/plants/stewart_platform.py: sim/stewart.py's legs under their PID
servos, a 3 kg payload off centre) driven along a continuous multi-sine trajectory of poses.
The controller commands the legs by the nominal inverse kinematics once per sample
(RATE_HZ, zero-order hold: a command holds until the next sample); every sample records the
commands, the leg encoders and a motion capture of the platform (0.05 mm / 0.02 deg per
sample, issue 6's figures). The truth goes to the answer, never into the recording.

The trajectory: REST_S at rest at home, then a slow multi-sine (0.08-0.25 Hz, peak leg speed
4 mm/s, platform ~2 mm/s) for the first 60 % of the recording, blended over BLEND_S into a
fast one (0.4-0.9 Hz, peak leg speed 16 mm/s, platform ~7 mm/s) for the last 40 % (the
diagnosis's held-out share). The speeds are capped because the PID's integral carries
kv * leg speed and clamps at leg_imax (300 N): at 40 mm/s it saturates, a nonlinearity that is
a fault of its own. Per effect, the physics and its concealment:

- ``leg_servo_lag``: the leg servos act on their commands ``magnitude`` seconds late (a drive
  bus / controller cycle latency common to all six axes), built as MuJoCo's own actuator
  ``delay`` (history buffer, linear interpolation). Concealed: invisible at rest (a rest-hold
  recording cannot see it) and invisible to the kinematics (the legs really are where the
  encoders say, so platform pose and measured legs agree); only the tracking of measured
  against commanded legs, in motion, carries it.
- ``mocap_latency``: the motion capture reports the pose ``magnitude`` seconds late relative
  to the encoders, built as MuJoCo sensor ``delay`` on the platform pose sensors. Concealed:
  invisible at rest; in the slow training motion the pose error v * tau stays below the
  per-sample mocap noise (10 ms: ~0.4 sigma), only the fast held-out motion shows it plainly
  (~0.8 sigma RMS per sample).

``magnitude`` None takes DEFAULT_MAGNITUDE; the blind bench draws from MAGNITUDE_RANGE.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pyarrow as pa
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import inverse_kinematics
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.stewart_platform import PlatformPlant, Reality, platform_spec
from serpar.sim.recording import PhaseSegment, Recording, RecordingMeta
from serpar.sim.stewart import StewartConfig
from serpar.twins.stewart_twin import (  # the same payload, encoders and motion capture
    LEG_SIGMA_M,
    MOCAP,
    PAYLOAD_COM_M,
    PAYLOAD_KG,
    mocap_quaternion,
    stewart_channels,
)

Vec = NDArray[np.float64]

EFFECTS: tuple[str, ...] = ("leg_servo_lag", "mocap_latency")
DEFAULT_MAGNITUDE: dict[str, float] = {"leg_servo_lag": 2e-3, "mocap_latency": 10e-3}
MAGNITUDE_RANGE: dict[str, tuple[float, float]] = {
    "leg_servo_lag": (0.5e-3, 5e-3),   # s: one to ten 500 us bus cycles
    "mocap_latency": (5e-3, 25e-3),    # s: a camera frame and its processing
}
UNITS = {"leg_servo_lag": "s", "mocap_latency": "s"}
RATE_HZ = 200.0
DURATION_S = 15.0
REST_S, RAMP_S, BLEND_S = 0.5, 1.0, 1.5
HOLDOUT_SHARE = 0.4
SLOW_HZ, FAST_HZ = (0.08, 0.25), (0.4, 0.9)
SLOW_AMP = (0.003, np.radians(0.6))
FAST_AMP = (0.006, np.radians(1.2))
"""(position [m], tilt [rad]) relative amplitude of each of the two sines per pose axis."""
SLOW_LEG_SPEED, FAST_LEG_SPEED = 4e-3, 16e-3
"""Peak leg speed [m/s] of the slow and the fast multi-sine."""
STROKE_MARGIN_M = 2e-3
MAX_DELAY_S = 0.1


def _magnitude(effect: str | None, magnitude: float | None) -> float:
    if effect is not None and effect not in EFFECTS:
        raise ConfigError(f"unknown Stewart motion effect {effect!r}; valid: "
                          f"{', '.join(EFFECTS)} (or none)")
    if effect is None:
        return 0.0
    mag = DEFAULT_MAGNITUDE[effect] if magnitude is None else float(magnitude)
    lo, hi = MAGNITUDE_RANGE[effect]
    if not (np.isfinite(mag) and 0 < mag <= MAX_DELAY_S):
        raise ConfigError(f"magnitude {magnitude!r} for {effect}: valid 0 < x <= {MAX_DELAY_S:g} "
                          f"{UNITS[effect]} (blind-bench range {lo:g}..{hi:g})")
    return mag


def _smoothstep(x: Vec) -> Vec:
    """Minimum-jerk blend 0 -> 1 over x in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return x**3 * (10.0 - 15.0 * x + 6.0 * x**2)


def _sines(t: Vec, band: tuple[float, float], amp: tuple[float, float],
           rng: np.random.Generator) -> Vec:
    """(n, 6) offsets: two sines per pose axis (x, y, z, rx, ry, rz) in the band [Hz]."""
    f = rng.uniform(*band, (6, 2))
    phase = rng.uniform(0.0, 2 * np.pi, (6, 2))
    scale = np.r_[[amp[0]] * 3, [amp[1]] * 3][:, None] * rng.uniform(0.6, 1.0, (6, 2))
    return np.einsum("dj,ndj->nd", scale, np.sin(2 * np.pi * f[None] * t[:, None, None] + phase))


def _strokes(geom: object, off: Vec) -> tuple[Vec, Vec, Vec]:
    pos = np.asarray(geom.home_pos) + off[:, :3]  # type: ignore[attr-defined]
    rot = Rotation.from_rotvec(off[:, 3:]).as_matrix()
    return pos, rot, inverse_kinematics(geom, pos, rot)  # type: ignore[arg-type]


def trajectory(rng: np.random.Generator, t: Vec, geom: object) -> tuple[Vec, Vec, Vec]:
    """Poses (n, 3), (n, 3, 3) and nominal commanded strokes (n, 6) at the sample times. Each
    multi-sine is scaled to its peak leg speed (the PID's integral, which carries kv * leg
    speed, must stay inside its clamp: a servo run into saturation is another fault)."""
    cut = (1.0 - HOLDOUT_SHARE) * DURATION_S
    parts = []
    for band, amp, speed in ((SLOW_HZ, SLOW_AMP, SLOW_LEG_SPEED), (FAST_HZ, FAST_AMP,
                                                                    FAST_LEG_SPEED)):
        off = _sines(t, band, amp, rng)
        peak = np.max(np.abs(np.gradient(_strokes(geom, off)[2], t, axis=0)))
        parts.append(off * speed / peak)
    mix = _smoothstep((t - (cut - BLEND_S)) / BLEND_S)[:, None]
    env = _smoothstep((t - REST_S) / RAMP_S)[:, None]
    for _ in range(20):
        pos, rot, s = _strokes(geom, env * ((1.0 - mix) * parts[0] + mix * parts[1]))
        if np.all((s > STROKE_MARGIN_M) & (s < geom.stroke - STROKE_MARGIN_M)):  # type: ignore[attr-defined]
            return pos, rot, s
        env = 0.85 * env  # shrink until every stroke keeps its margin
    raise ConfigError("no trajectory within the stroke margins")


def _delayed_plant(reality: Reality, servo_s: float, mocap_s: float, start: Vec
                   ) -> tuple[mujoco.MjModel, mujoco.MjData, PlatformPlant]:
    """The twin's MuJoCo platform with actuator / pose-sensor delays, at rest at ``start``
    strokes (settled without delays, then the history buffers filled with the rest)."""
    plant = PlatformPlant(reality)
    geom = plant.cfg.geometry()
    plant.settle(start, 0.0, (np.asarray(geom.home_pos), np.eye(3)))
    spec, _ = platform_spec(reality, PhysicsConfig(sleep=False))
    dt = spec.option.timestep
    for act in spec.actuators:
        if servo_s > 0:
            act.delay, act.nsample, act.interp = servo_s, int(np.ceil(servo_s / dt)) + 3, 1
    for sen in spec.sensors:
        if mocap_s > 0 and sen.name in ("platform_pos", "platform_quat"):
            sen.delay, sen.nsample, sen.interp = mocap_s, int(np.ceil(mocap_s / dt)) + 3, 1
    m = spec.compile()
    d = mujoco.MjData(m)
    src = plant.data
    d.qpos[:], d.qvel[:], d.act[:], d.ctrl[:] = src.qpos, src.qvel, src.act, src.ctrl
    mujoco.mj_forward(m, d)
    for a in range(m.nu):
        if m.actuator_history[a, 0] > 0:
            mujoco.mj_initCtrlHistory(m, d, a, None,
                                      np.full((m.actuator_history[a, 0], 1), src.ctrl[a]))
    site = m.site("platform_centre").id
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, d.site_xmat[site])
    rest = {"platform_pos": d.site_xpos[site].copy(), "platform_quat": quat}
    for name, value in rest.items():  # a delayed sensor reads its (empty) history: fill it
        s = m.sensor(name).id
        n = int(m.sensor_history[s, 0])
        if n > 0:
            mujoco.mj_initSensorHistory(m, d, s, None, np.tile(value, (n, 1)), 0.0)
    return m, d, plant


def simulate(reality: Reality, strokes: Vec, rate_hz: float, servo_s: float = 0.0,
             mocap_s: float = 0.0) -> tuple[Vec, Vec, Vec]:
    """Slides (n, 6) at the sample instants, and the pose (n, 3), (n, 4 wxyz) the pose sensors
    report there, with ``strokes`` (n, 6) held from each sample to the next."""
    m, d, plant = _delayed_plant(reality, servo_s, mocap_s, strokes[0])
    steps = round(1.0 / (rate_hz * m.opt.timestep))
    pos_adr = m.sensor_adr[m.sensor("platform_pos").id]
    quat_adr = m.sensor_adr[m.sensor("platform_quat").id]
    n = len(strokes)
    slides, pos, quat = np.zeros((n, 6)), np.zeros((n, 3)), np.zeros((n, 4))
    for k in range(n):
        slides[k] = d.qpos[plant.slide_q]
        d.ctrl[:] = strokes[k]
        mujoco.mj_step(m, d)  # its sensors are those of the state at the sample instant
        pos[k] = d.sensordata[pos_adr:pos_adr + 3]
        quat[k] = d.sensordata[quat_adr:quat_adr + 4]
        mujoco.mj_step(m, d, nstep=steps - 1)
    if d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
        raise ConfigError("the twin platform went unstable along its trajectory")
    return slides, pos, quat / np.linalg.norm(quat, axis=1, keepdims=True)


def make_twin(effect: str | None, magnitude: float | None, seed: int
              ) -> tuple[Recording, dict[str, object]]:
    """The recording of a moving platform with ``effect`` (None: no hidden effect) and the
    answer (effect, magnitude, the latency in seconds)."""
    mag = _magnitude(effect, magnitude)
    rng = np.random.default_rng([seed, 23])
    cfg = StewartConfig()
    t = np.arange(round(DURATION_S * RATE_HZ)) / RATE_HZ
    _, _, cmd = trajectory(rng, t, cfg.geometry())
    reality = Reality(payload_kg=PAYLOAD_KG, payload_com_m=PAYLOAD_COM_M)
    servo = mag if effect == "leg_servo_lag" else 0.0
    mocap = mag if effect == "mocap_latency" else 0.0
    slides, pos, quat = simulate(reality, cmd, RATE_HZ, servo, mocap)
    rec = _recording(t, cmd, slides, pos, quat, cfg, rng)
    params = {"tau_s": mag} if effect else {}
    answer = {"effect": effect or "none", "magnitude": mag,
              "magnitude_unit": UNITS.get(effect or "", ""), "seed": seed, "params": params,
              "duration_s": DURATION_S, "rate_hz": RATE_HZ}
    return rec, answer


def _recording(t: Vec, cmd: Vec, slides: Vec, pos: Vec, quat: Vec, cfg: StewartConfig,
               rng: np.random.Generator) -> Recording:
    n = len(t)
    sigma_a = np.radians(MOCAP.angle_deg)
    mp = pos + MOCAP.position_m * rng.standard_normal((n, 3))
    q = mocap_quaternion(Rotation.from_quat(quat[:, [1, 2, 3, 0]]), sigma_a, rng)
    legs = cfg.l_min + slides + LEG_SIGMA_M * rng.standard_normal((n, 6))
    cols, sigma = stewart_channels(t, cfg.l_min + cmd, legs, mp, q, sigma_a)
    model = {"stewart": {"l_min": cfg.l_min, "stroke": cfg.stroke, "home_z": cfg.home_z,
                         "swap_legs12": cfg.swap_legs12, "payload_kg": PAYLOAD_KG,
                         "payload_com_m": list(PAYLOAD_COM_M),
                         "command": "zero-order hold from each sample to the next"},
             "instrument": f"motion capture and leg encoders at {RATE_HZ:g} Hz, white noise",
             "notes": {"leg": "encoder reading l_min + stroke [m]",
                       "leg_cmd": "l_min + commanded stroke (nominal inverse kinematics), "
                                  "held until the next sample",
                       "platform_q": "noise_sigma of a quaternion component: half the "
                                     "rotation noise per axis [rad]"}}
    meta = RecordingMeta(source="sim", sample_rate_hz=RATE_HZ, channels=tuple(cols),
                         noise_sigma=sigma, phases=(PhaseSegment("motion", 0.0, float(t[-1])),),
                         model=model)
    return Recording(meta, pa.table(cols))
