"""A Stewart platform recording (docs/recording.md) as rest holds for the diagnosis.

Signals: ``leg_cmd1..6`` (commanded leg lengths l_min + stroke [m]), ``leg1..6`` (measured leg
lengths [m]) and ``platform_x/y/z``, ``platform_qw/qx/qy/qz`` (the platform pose a motion
capture or tracker saw, Stewart base frame). ``meta.noise_sigma`` gives the per-sample noise of
the platform channels (quaternion components: half the rotation noise per axis) and, when the
encoders have any, of the legs. ``meta.model["stewart"]`` may name the nominal platform
(``l_min``, ``stroke``, ``home_z``, ``swap_legs12``) and a payload (``payload_kg``,
``payload_com_m`` in the platform frame); absent keys take sim/stewart.py's defaults.

The model is quasi-static, so it is compared with the platform at rest: a *hold* is a run of
samples with one leg command in which every measured leg is within REST_TOL_M of it (the servo
has settled). Samples outside holds are counted and reported, never silently dropped; each
hold is reduced to its mean (the noise of a mean is sigma / sqrt(n)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.kinematics.rotations import quat_to_rot
from serpar.sim import channels as ch
from serpar.sim.recording import Recording
from serpar.sim.stewart import StewartConfig
from serpar.sim.stewart_statics import Load, nominal_load

Vec = NDArray[np.float64]
LEGS, CMDS, POSE = ch.LEG, ch.LEG_CMD, ch.PLATFORM_POSITION + ch.PLATFORM_QUAT
CHANNELS = CMDS + LEGS + POSE
CHANNELS_HELP = ("leg_cmd1..6 and leg1..6 (leg lengths l_min + stroke [m]), platform_x/y/z [m] "
                 "and platform_qw/qx/qy/qz (platform pose in the Stewart base frame)")
CMD_TOL_M = 1e-9
"""Consecutive samples with leg commands this close belong to one hold."""
REST_TOL_M = 2e-6
"""A sample is at rest when every measured leg is this close to its command."""
MIN_HOLD = 5
MIN_HOLDS = 20
LEG_MARGIN_M = 5e-3
QUAT_TOL = 1e-3
CONFIG_KEYS = ("l_min", "stroke", "home_z", "swap_legs12")


@dataclass(frozen=True)
class StewartHolds:
    """Per-hold means of a recording, and what the mean's noise is."""

    time: Vec
    """(n,) mean time of each hold since the recording's first sample [s]."""
    legs: Vec
    """(n, 6) measured leg lengths [m]."""
    cmd: Vec
    pos: Vec
    """(n, 3) measured platform position [m]."""
    rot: Vec
    """(n, 3, 3) measured platform orientation (chordal mean of the samples)."""
    count: NDArray[np.int64]
    sigma_pos: float
    """Per sample and axis [m]."""
    sigma_rot: float
    """Per sample and axis [rad]."""
    sigma_leg: float
    n_samples: int
    n_excluded: int
    """Samples not at rest (moving, or settling after a new command)."""
    config: dict[str, object]
    """Keyword arguments of the nominal StewartConfig."""
    load: Load
    scatter_pos: float = float("nan")
    """Per sample and axis [m]: the pooled scatter of the position samples about their hold's
    mean, the noise the data themselves show (nan with too few samples)."""

    @property
    def n(self) -> int:
        return len(self.time)


def _column(rec: Recording, name: str) -> Vec:
    col = rec.signals.column(name)
    if col.null_count:
        raise IdentificationError(f"channel {name} has {col.null_count} missing sample(s)")
    x = np.asarray(col.to_numpy(zero_copy_only=False), float)
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise IdentificationError(f"channel {name} has {bad.size} non-finite sample(s) (NaN/inf), "
                                  f"first at row {bad[0]}")
    return x


def _sigma(rec: Recording, names: tuple[str, ...], required: bool) -> float:
    sig = rec.meta.noise_sigma
    missing = [n for n in names if n not in sig]
    if missing and required:
        raise IdentificationError(f"meta.json noise_sigma lacks {', '.join(missing)}: the "
                                  "diagnosis judges 'beyond noise' against it (platform position "
                                  "[m] per axis, quaternion components [-])")
    vals = [float(sig[n]) for n in names if n in sig]
    if any(not (np.isfinite(v) and v >= 0) for v in vals) or (required and min(vals) <= 0):
        raise IdentificationError(f"noise_sigma of {', '.join(names)} must be positive, got {vals}")
    return float(np.mean(vals)) if vals else 0.0


def _stewart_meta(rec: Recording) -> dict[str, object]:
    given = rec.meta.model.get("stewart", {}) if isinstance(rec.meta.model, dict) else {}
    if not isinstance(given, dict):
        raise IdentificationError("meta.model['stewart'] must be an object naming l_min, stroke, "
                                  "home_z, swap_legs12, payload_kg, payload_com_m")
    return given


def _platform(rec: Recording) -> tuple[StewartConfig, Load]:
    """The nominal platform and its load, from meta.model["stewart"] (defaults otherwise)."""
    given = _stewart_meta(rec)
    try:
        cfg = StewartConfig(**{k: given[k] for k in CONFIG_KEYS if k in given})  # type: ignore[arg-type]
        mass = float(given.get("payload_kg", 0.0))  # type: ignore[arg-type]
        com = tuple(float(v) for v in given.get("payload_com_m", (0.0, 0.0, 0.0)))  # type: ignore[attr-defined]
        if not (np.isfinite(mass) and mass >= 0 and len(com) == 3 and np.all(np.isfinite(com))):
            raise ValueError(f"a payload needs payload_kg >= 0 and payload_com_m = 3 numbers [m], "
                             f"got {mass}, {list(com)}")
    except (TypeError, ValueError) as exc:
        raise IdentificationError(f"meta.model['stewart'] does not describe a platform: {exc} "
                                  f"(keys: {', '.join(CONFIG_KEYS)}, payload_kg, payload_com_m)") from None
    return cfg, nominal_load(mass, com)  # type: ignore[arg-type]


def require_channels(rec: Recording, what: str) -> None:
    """IdentificationError (one line) naming the Stewart channels ``rec`` lacks."""
    cols = set(rec.signals.column_names)
    missing = [c for c in CHANNELS if c not in cols]
    if missing:
        raise IdentificationError(f"{what} needs channels {', '.join(missing)} "
                                  f"(valid set: {CHANNELS_HELP}); it has "
                                  f"{', '.join(sorted(cols - {'time'})) or 'no channels'}")


def read_stewart(rec: Recording) -> StewartHolds:
    """The holds of a Stewart recording; IdentificationError (one line) names what is wrong."""
    require_channels(rec, "a Stewart recording")
    cfg, load = _platform(rec)
    t = _column(rec, "time")
    cmd = np.column_stack([_column(rec, c) for c in CMDS])
    legs = np.column_stack([_column(rec, c) for c in LEGS])
    lo, hi = cfg.l_min - LEG_MARGIN_M, cfg.l_min + cfg.stroke + LEG_MARGIN_M
    for name, x in zip(CMDS + LEGS, np.hstack([cmd, legs]).T):
        if x.min() < lo or x.max() > hi:
            raise IdentificationError(
                f"{name} ranges {x.min():.6g}..{x.max():.6g}, outside the nominal platform's leg "
                f"lengths {cfg.l_min:.4f}..{cfg.l_min + cfg.stroke:.4f} m (+-5 mm): leg channels "
                "are joint-to-joint lengths l_min + stroke in metres (strokes? millimetres?)")
    pos = np.column_stack([_column(rec, c) for c in POSE[:3]])
    quat = np.column_stack([_column(rec, c) for c in POSE[3:]])
    far = np.max(np.linalg.norm(pos - cfg.home_pos, axis=1))
    if far > 0.2:
        raise IdentificationError(f"platform_x/y/z reach {far:.3g} from the home pose "
                                  f"{tuple(cfg.home_pos)} m: not metres in the Stewart base frame")
    norm = np.linalg.norm(quat, axis=1)
    if np.max(np.abs(norm - 1.0)) > QUAT_TOL:
        k = int(np.argmax(np.abs(norm - 1.0)))
        raise IdentificationError(f"platform_qw/qx/qy/qz is not a unit quaternion at row {k} "
                                  f"(norm {norm[k]:.6g})")
    sigma_pos = _sigma(rec, POSE[:3], True)
    sigma_rot = 2.0 * _sigma(rec, POSE[4:], True)
    sigma_leg = _sigma(rec, LEGS, False)
    return _holds(t, cmd, legs, pos, quat / norm[:, None], sigma_pos, sigma_rot, sigma_leg,
                  cfg, load)


def _holds(t: Vec, cmd: Vec, legs: Vec, pos: Vec, quat: Vec, sigma_pos: float,
           sigma_rot: float, sigma_leg: float, cfg: StewartConfig, load: Load) -> StewartHolds:

    new = np.r_[True, np.any(np.abs(np.diff(cmd, axis=0)) > CMD_TOL_M, axis=1)]
    run = np.cumsum(new) - 1
    rest = np.all(np.abs(legs - cmd) <= REST_TOL_M, axis=1)
    ids = np.unique(run[rest])
    counts = np.array([np.sum(rest & (run == r)) for r in ids], np.int64)
    keep = ids[counts >= MIN_HOLD]
    if keep.size < MIN_HOLDS:
        raise IdentificationError(
            f"{keep.size} rest holds found; the Stewart diagnosis needs at least {MIN_HOLDS} (a "
            f"hold: >= {MIN_HOLD} samples at one leg command with every leg within "
            f"{REST_TOL_M * 1e6:g} um of it)")
    used = rest & np.isin(run, keep)
    rot = quat_to_rot(quat)
    out: dict[str, list] = {k: [] for k in ("time", "legs", "cmd", "pos", "rot", "count")}
    ss, dof = 0.0, 0
    for r in keep:
        m = used & (run == r)
        ss += float(np.sum((pos[m] - pos[m].mean(axis=0)) ** 2))
        dof += 3 * (int(m.sum()) - 1)
        out["time"].append(t[m].mean() - t[0])
        out["legs"].append(legs[m].mean(axis=0))
        out["cmd"].append(cmd[m].mean(axis=0))
        out["pos"].append(pos[m].mean(axis=0))
        u, _, vt = np.linalg.svd(rot[m].mean(axis=0))  # chordal mean: nearest rotation
        out["rot"].append(u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt)
        out["count"].append(int(m.sum()))
    cfg_kwargs = {k: getattr(cfg, k) for k in CONFIG_KEYS}
    return StewartHolds(np.array(out["time"]), np.array(out["legs"]), np.array(out["cmd"]),
                        np.array(out["pos"]), np.array(out["rot"]),
                        np.array(out["count"], np.int64), sigma_pos, sigma_rot, sigma_leg,
                        len(t), int(len(t) - used.sum()), cfg_kwargs, load,
                        float(np.sqrt(ss / dof)) if dof >= 30 else float("nan"))
