"""Concealed-effect twins of a Stewart platform campaign (issue 7): the "real" platform is
MuJoCo's (sim/plants/stewart_platform.py), commanded through its nominal inverse kinematics to a
set of poses; at each pose it rests for a 1 s hold in which the leg encoders and a motion
capture system (100 Hz, 0.05 mm / 0.02 deg per sample, issue 6's figures) are recorded. The
truth goes to the answer, never into the recording.

Every twin carries the same known payload (a 3 kg fixture off the platform centre, written
into ``meta.model["stewart"]`` like the nominal platform's own numbers), so the legs carry
loads that change from pose to pose. Per effect, the physics and how it is concealed (the
diagnosis holds out the last 40 % of the holds in time):

- ``stewart_geometry``: joint-position and leg-length errors built into the MuJoCo model,
  drawn per seed with seed 000 Table 5's RMS per column, x magnitude. Concealed: the first
  60 % of the poses lie in a narrow box (+-25 mm, +-3 deg) where per-leg length offsets
  explain most of it; the last 40 % span the workspace (+-40 mm, +-5 deg).
- ``leg_thermal_drift``: the legs (steel, 11.5e-6/K) warm linearly by ``magnitude`` K over the
  15 min campaign (motors heating their cylinders), so every rod stands out further by
  alpha dT(t) L. Concealed: the hold-out is the last 40 % in time, an extrapolation.
- ``leg_compliance``: a passive spring of compliance ``magnitude`` [m/N] (+-20 % per leg;
  default 5e-8 m/N = 20 N/um, a small ball-screw leg) in series with each actuated slide.
  Concealed: narrow poses first (+-15 mm, +-2 deg), then the workspace; on the narrow set
  the geometric parameters absorb the deflection to the noise floor.
- ``leg_encoder_offset``: per-leg encoder zero offsets, the largest ``magnitude`` [m]: the servo
  holds the encoder at the command, so the leg stands short by the offset while its channel
  reads the command. Geometry's leg-length errors can absorb it; the diagnosis must prefer
  the 6 offsets to the 42 geometric parameters on held-out data.

Two more, each with its own candidate in the library since real platforms show them; the
blind bench also draws them with that candidate withheld (``WITHHELD``), as physics outside
the library, scored by the ``signature`` their answers carry (the channels, the variable the
residual follows and a sentence):

- ``leg_thermal_nonuniform``: two legs (drawn) warm towards steady temperatures, leg i by
  dT_i(t) = dT_i,max (1 - exp(-t / tau_i)), tau_i drawn 2-6 min (a motor heating its own
  cylinder), dT_max ``magnitude`` K for one and 0.5-1 x that for the other; the other four
  stay cold. Unlike ``leg_thermal_drift``, neither uniform nor linear in time.
- ``leg_encoder_scale``: one leg's encoder (drawn) reads its stroke x (1 + s), |s| =
  ``magnitude``, random sign (a lead error of the screw or a mis-set encoder resolution): the
  servo holds the reading at the command, so that leg stands short or long in proportion to
  its stroke, which a constant offset cannot follow.

``magnitude`` None takes DEFAULT_MAGNITUDE; the blind bench draws from MAGNITUDE_RANGE. A hold
still moving after MAX_SETTLE_S of simulated settling is counted in the answer
(``unsettled_holds``), not hidden.
"""

from __future__ import annotations

from typing import cast

import numpy as np
import pyarrow as pa
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from serpar.calibration.stewart_campaign import MocapNoise, random_poses
from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import inverse_kinematics
from serpar.kinematics.stewart_table import table5_errors
from serpar.sim import channels as ch
from serpar.sim.plants.stewart_platform import MAX_SETTLE_S, PlatformPlant, Reality
from serpar.sim.recording import PhaseSegment, Recording, RecordingMeta
from serpar.sim.stewart import StewartConfig

Vec = NDArray[np.float64]

OUT_OF_LIBRARY: tuple[str, ...] = ()
"""Effects the diagnosis has no candidate for: they must come out as unexplained residual."""
WITHHELD: tuple[str, ...] = ("leg_thermal_nonuniform", "leg_encoder_scale")
"""Library effects the blind bench also draws with their candidate withheld from the
diagnosis: physics outside the library, with a signature to score the empirical term by."""
PARTLY_IN_LIBRARY: dict[str, tuple[str, ...]] = {
    "leg_thermal_nonuniform": ("leg_thermal_drift", "leg_encoder_offset"),
    "leg_encoder_scale": ("leg_encoder_offset",),
}
"""Library effects that express part of an effect's physics (not a wrong finding when
established with it, or for it while its candidate is withheld): a warmed leg is a constant
length error once warm and a drift while warming; a scale error's mean over the strokes is a
constant length error. Joint-position errors are not: the joints are where they were built."""
EFFECTS: tuple[str, ...] = ("stewart_geometry", "leg_thermal_drift", "leg_compliance",
                            "leg_encoder_offset", *WITHHELD)
DEFAULT_MAGNITUDE: dict[str, float] = {"stewart_geometry": 1.0, "leg_thermal_drift": 5.0,
                                       "leg_compliance": 5e-8, "leg_encoder_offset": 5e-5,
                                       "leg_thermal_nonuniform": 40.0, "leg_encoder_scale": 2e-3}
MAGNITUDE_RANGE: dict[str, tuple[float, float]] = {
    "stewart_geometry": (0.3, 1.5),     # x Table 5 RMS
    "leg_thermal_drift": (3.0, 10.0),   # K of warming over the campaign
    "leg_compliance": (2e-8, 1e-7),     # m/N (50 to 10 N/um)
    "leg_encoder_offset": (2e-5, 2e-4),  # m, the largest of the six
    "leg_thermal_nonuniform": (20.0, 60.0),  # K, the warmer leg's steady warming
    "leg_encoder_scale": (1e-3, 3e-3),  # |relative scale error| of the one leg (below 1e-3 the
    # geometry and compliance candidates absorb it to ~2x the noise)
}
UNITS = {"stewart_geometry": "x Table 5", "leg_thermal_drift": "K", "leg_compliance": "m/N",
         "leg_encoder_offset": "m", "leg_thermal_nonuniform": "K", "leg_encoder_scale": "1"}
N_POSES = 150
HOLDOUT_SHARE = 0.4
"""Share of the poses (the last in time) the diagnosis holds out; the twin's narrow poses
fill the rest."""
NARROW = {"stewart_geometry": (0.025, 3.0), "leg_compliance": (0.015, 2.0)}
WIDE = (0.04, 5.0)
"""(reach [m], tilt [deg]) of the pose boxes about home: the training box of the effects
concealed by a narrow pose set, and the workspace. Geometry's box is as narrow as lets 42
parameters extrapolate to the workspace within 1.3x the noise (20 seeds; +-20 mm, +-3 deg
reached 1.47x); compliance's is narrower, so the 42 parameters that absorb its deflection on
the training holds extrapolate visibly worse than 6 compliances."""
STROKE_MARGIN_M = 0.5e-3
"""Poses keep every commanded stroke this far inside [0, stroke] (room for the offsets)."""
POSE_PERIOD_S = 6.0
HOLD_S, RATE_HZ = 1.0, 100.0
SETTLE_BEFORE_HOLD_S = 4.0
"""Each pose period: move and settle, then the 1 s hold that is recorded."""
STEEL_PER_K = 11.5e-6
THERMAL_TAU_S = (120.0, 360.0)
"""Range of the legs' thermal time constants: a few minutes for a motor-heated cylinder."""
PAYLOAD_KG = 3.0
PAYLOAD_COM_M = (0.03, -0.02, 0.05)
LEG_SIGMA_M = 5e-8
"""Leg encoder noise per sample [m] (an interpolated ball-screw encoder)."""
MOCAP = MocapNoise()


def _magnitude(effect: str | None, magnitude: float | None) -> float:
    if effect is not None and effect not in EFFECTS:
        raise ConfigError(f"unknown Stewart effect {effect!r}; valid: {', '.join(EFFECTS)} "
                          "(or none)")
    if effect is None:
        return 0.0
    mag = DEFAULT_MAGNITUDE[effect] if magnitude is None else float(magnitude)
    lo, hi = MAGNITUDE_RANGE[effect]
    if not (np.isfinite(mag) and 0 < mag <= 5 * hi):
        raise ConfigError(f"magnitude {magnitude!r} for {effect}: valid 0 < x <= {5 * hi:g} "
                          f"{UNITS[effect]} (blind-bench range {lo:g}..{hi:g})")
    return mag


def _poses(effect: str | None, n: int, rng: np.random.Generator) -> tuple[Vec, Vec]:
    """Poses in measurement order: narrow then wide for the effects concealed that way."""
    geom = StewartConfig().geometry()
    n_held = round(HOLDOUT_SHARE * n)
    boxes = [(NARROW[effect], n - n_held), (WIDE, n_held)] if effect in NARROW else [(WIDE, n)]
    pos, rot = [], []
    for (reach, tilt), count in boxes:
        p, r = random_poses(3 * count, int(rng.integers(2**31)), geom, reach, tilt)
        s = inverse_kinematics(geom, p, r)
        ok = np.all((s > STROKE_MARGIN_M) & (s < geom.stroke - STROKE_MARGIN_M), axis=1)
        if ok.sum() < count:
            raise ConfigError(f"only {ok.sum()} of {3 * count} poses keep the stroke margin")
        pos.append(p[ok][:count])
        rot.append(r[ok][:count])
    return np.concatenate(pos), np.concatenate(rot)


def _reality(effect: str | None, mag: float, rng: np.random.Generator, duration: float
             ) -> tuple[Reality, dict[str, object]]:
    base = {"payload_kg": PAYLOAD_KG, "payload_com_m": PAYLOAD_COM_M}
    if effect == "stewart_geometry":

        rms = np.sqrt(np.mean(table5_errors()**2, axis=0))
        errors = mag * rms * rng.standard_normal((6, 7))
        return Reality(joint_errors=errors, **base), {"joint_errors_m": errors.tolist()}
    if effect == "leg_thermal_drift":
        kappa = STEEL_PER_K * mag / duration
        return Reality(growth_per_s=kappa, **base), {"kappa_per_s": kappa,
                                                     "expansion_per_k": STEEL_PER_K}
    if effect == "leg_compliance":
        c = mag * rng.uniform(0.8, 1.2, 6)
        return Reality(compliance_m_per_n=c, **base), {"compliance_m_per_n": c.tolist()}
    if effect == "leg_encoder_offset":
        o = rng.uniform(-1.0, 1.0, 6)
        o *= mag / np.max(np.abs(o))
        return Reality(encoder_offset_m=o, **base), {"encoder_offset_m": o.tolist()}
    if effect == "leg_thermal_nonuniform":
        legs = np.sort(rng.choice(6, 2, replace=False))
        dt_max = np.zeros(6)
        dt_max[legs] = rng.permutation([mag, mag * rng.uniform(0.5, 1.0)])
        tau = rng.uniform(*THERMAL_TAU_S, 6)  # every leg has one; only two warm
        reality = Reality(growth_saturation=STEEL_PER_K * dt_max, growth_tau_s=tau, **base)
        return reality, {"legs": (legs + 1).tolist(), "dT_max_k": dt_max[legs].tolist(),
                         "tau_s": tau[legs].tolist(), "expansion_per_k": STEEL_PER_K,
                         "growth_saturation": reality.growth_saturation.tolist()}
    if effect == "leg_encoder_scale":
        leg = int(rng.integers(6))
        scale = np.zeros(6)
        scale[leg] = mag * rng.choice([-1.0, 1.0])
        return Reality(encoder_scale=scale, **base), {"leg": leg + 1, "scale": float(scale[leg]),
                                                      "encoder_scale": scale.tolist()}
    return Reality(**base), {}


def _signature(effect: str | None, params: dict[str, object]) -> dict[str, object] | None:
    """Where an out-of-library effect shows: channels, the variable it follows, in words."""
    if effect == "leg_thermal_nonuniform":
        legs = cast(list[int], params["legs"])
        return {"channels": [f"leg {i}" for i in legs], "variables": ["time"],
                "words": f"legs {legs[0]} and {legs[1]} grow by themselves, quickly at first and "
                         "then levelling off over the campaign (saturating warm-up); the other "
                         "legs do not"}
    if effect == "leg_encoder_scale":
        leg = cast(int, params["leg"])
        return {"channels": [f"leg {leg}"], "variables": [f"stroke {leg}"],
                "words": f"leg {leg} is off by an amount proportional to its own stroke "
                         "(encoder scale error), zero at the encoder zero"}
    return None


def make_twin(effect: str | None, magnitude: float | None, seed: int, n_poses: int = N_POSES
              ) -> tuple[Recording, dict[str, object]]:
    """The recording of a campaign on a platform with ``effect`` (None: no hidden effect) and
    the answer (effect, magnitude, physical parameters, settling statistics)."""
    mag = _magnitude(effect, magnitude)
    if not 20 <= n_poses <= 1000:
        raise ConfigError(f"n_poses {n_poses}: valid 20..1000")
    rng = np.random.default_rng([seed, 11])
    duration = n_poses * POSE_PERIOD_S
    reality, params = _reality(effect, mag, rng, duration)
    pos, rot = _poses(effect, n_poses, rng)
    cfg = StewartConfig()
    geom = cfg.geometry()
    plant = PlatformPlant(reality)
    cmd = inverse_kinematics(geom, pos, rot)  # what the platform's nominal model commands
    start = np.arange(n_poses) * POSE_PERIOD_S + SETTLE_BEFORE_HOLD_S
    n_hold = round(HOLD_S * RATE_HZ)
    true_pos, true_rot, slides, settle = [], [], [], []
    for k in range(n_poses):
        # the servo holds the encoder (true stroke x (1 + scale) + offset) at the command
        p, r, s, el = plant.settle(reality.stroke_for_reading(cmd[k]),
                                   float(start[k] + 0.5 * HOLD_S), (pos[k], rot[k]))
        true_pos.append(p), true_rot.append(r), slides.append(s), settle.append(el)
    rec = _recording(np.array(true_pos), np.array(true_rot), np.array(slides), cmd, start,
                     n_hold, reality, cfg, rng)
    answer = {"effect": effect or "none", "magnitude": mag, "magnitude_unit": UNITS.get(effect or "", ""),
              "seed": seed, "params": params, "n_poses": n_poses,
              "settle_s_max": float(np.max(settle)), "settle_s_mean": float(np.mean(settle)),
              "unsettled_holds": int(np.sum(np.asarray(settle) >= MAX_SETTLE_S - 1e-9))}
    signature = _signature(effect, params)
    if signature is not None:
        answer["signature"] = signature
    return rec, answer


def mocap_quaternion(true: Rotation, sigma_a: float, rng: np.random.Generator) -> Vec:
    """(n, 4) w-first unit quaternions that motion capture reads for the `true` rotations:
    a white rotation noise of `sigma_a` [rad] per axis, sign fixed to w >= 0."""
    noise = sigma_a * rng.standard_normal((len(true), 3))
    xyzw = (Rotation.from_rotvec(noise) * true).as_quat()
    return np.column_stack([xyzw[:, 3], xyzw[:, :3]]) * np.sign(xyzw[:, 3:4] + 1e-300)


def stewart_channels(t: Vec, leg_cmd: Vec, legs: Vec, position: Vec, quat: Vec, sigma_a: float
                     ) -> tuple[dict[str, Vec], dict[str, float]]:
    """A platform recording's columns (schema names) and their noise sigma: commanded and
    measured leg lengths [m], the motion-capture pose (quaternion sigma: half the rotation's)."""
    cols: dict[str, Vec] = {ch.TIME: t}
    cols.update({c: leg_cmd[:, i] for i, c in enumerate(ch.LEG_CMD)})
    cols.update({c: legs[:, i] for i, c in enumerate(ch.LEG)})
    cols.update({c: position[:, j] for j, c in enumerate(ch.PLATFORM_POSITION)})
    cols.update({c: quat[:, j] for j, c in enumerate(ch.PLATFORM_QUAT)})
    sigma = {**{c: LEG_SIGMA_M for c in ch.LEG},
             **{c: MOCAP.position_m for c in ch.PLATFORM_POSITION},
             **{c: sigma_a / 2 for c in ch.PLATFORM_QUAT}}
    return cols, sigma


def _recording(pos: Vec, rot: Vec, slides: Vec, cmd: Vec, start: Vec, n_hold: int,
               reality: Reality, cfg: StewartConfig, rng: np.random.Generator) -> Recording:
    n = len(pos)
    t = (start[:, None] + np.arange(n_hold)[None, :] / RATE_HZ).ravel()
    idx = np.repeat(np.arange(n), n_hold)
    sigma_a = np.radians(MOCAP.angle_deg)
    mp = pos[idx] + MOCAP.position_m * rng.standard_normal((len(t), 3))
    quat = mocap_quaternion(Rotation.from_matrix(rot[idx]), sigma_a, rng)
    legs = cfg.l_min + slides[idx] * (1.0 + reality.encoder_scale) + reality.encoder_offset_m \
        + LEG_SIGMA_M * rng.standard_normal((len(t), 6))
    cols, sigma = stewart_channels(t, cfg.l_min + cmd[idx], legs, mp, quat, sigma_a)
    model = {"stewart": {"l_min": cfg.l_min, "stroke": cfg.stroke, "home_z": cfg.home_z,
                         "swap_legs12": cfg.swap_legs12, "payload_kg": PAYLOAD_KG,
                         "payload_com_m": list(PAYLOAD_COM_M)},
             "instrument": "motion capture at 100 Hz, white noise per sample; leg encoders",
             "notes": {"leg": "encoder reading l_min + stroke [m]",
                       "leg_cmd": "l_min + commanded stroke (nominal inverse kinematics)",
                       "platform_q": "noise_sigma of a quaternion component: half the "
                                     "rotation noise per axis [rad]"}}
    meta = RecordingMeta(source="sim", sample_rate_hz=RATE_HZ, channels=tuple(cols),
                         noise_sigma=sigma, phases=(PhaseSegment("campaign", 0.0, float(t[-1])),),
                         model=model)
    return Recording(meta, pa.table(cols))
