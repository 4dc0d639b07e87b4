"""Arm time series for the dynamics diagnosis: read and check a recording, and the one
smoothing kernel every compared quantity goes through.

Why smoothing, and why one kernel. Inverse dynamics needs q̈, and differentiating 20-bit
encoder readings twice at 1 kHz gives ~4 rad/s² of noise per sample. So every quantity —
the measured torques, the command, and the model's torque evaluated at *every* sample from
the raw second difference of q — is averaged by the same Hann window of ``window`` samples
and compared once per window (rows, one every ``window`` samples). Because the model is
linear in q̈ and evaluated before averaging, smoothing both sides by one kernel is
consistent to the 1 kHz sampling, not just to the window's polynomial order; a smooth
window (Hann, not Savitzky-Golay, whose sharp ends pass the differentiated quantisation
noise) keeps q̈'s noise ~40x lower (2.4e-3 rad/s² for a 51-sample window); rows a window apart have independent noise, which the
chi-square tests downstream assume.

Sampling model (what a row k's samples mean, see docs of sim/plants/moving_arm.py):
``q`` at t_k; ``tau_J`` the mean over the period ending at t_k (centred half a period
earlier); ``tau_J_d`` held over [t_k, t_k+1), so its continuous mean around t_k is the mean
of the commands k-1 and k.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import scipy.signal
from scipy.interpolate import BSpline, make_interp_spline
from scipy.ndimage import correlate1d
from numpy.typing import NDArray

from serpar.errors import IdentificationError
from serpar.sim import channels as ch
from serpar.sim.recording import Recording
from serpar.sim.rigid_arm import PANDA_ARM, ArmModel

Vec = NDArray[np.float64]

DRIVE_PREFIX = "tau_drive"
"""Drive torque on the joint side, computed from motor current or motor torque [N m]: what the
motor delivers, friction and rotor inertia inside the drive included (a measured torque, not a
command)."""
TORQUES = ("tau_J", DRIVE_PREFIX)
"""The measured torques; a recording needs one of them (dq is optional: velocities come from
the encoders; tau_J_d, the command, is optional)."""
RATE_TOLERANCE = 0.01
"""Largest relative deviation of a sampling interval from 1/sample_rate_hz."""
Q_MARGIN = 0.2
"""[rad] beyond a Panda joint limit that a recorded angle may reach (encoder offsets, tool
calibration); farther out the recording is of another robot or in degrees."""
MIN_ROWS = 40
"""Fewest comparison rows (windows) a recording must give."""
MAX_LATENCY_S = 0.03
"""[s] the longest actuation latency the diagnosis considers (the latency effect's bound); after
a break rows keep this much more clear, as that effect reads the command this far back."""


@dataclass(frozen=True)
class SmoothingConfig:
    window: int = 51
    """Hann window length [samples], odd; rows are this many samples apart."""

    def __post_init__(self) -> None:
        if self.window < 5 or self.window % 2 == 0:
            raise IdentificationError(f"SmoothingConfig.window={self.window}: an odd number >= 5")

    def kernel(self) -> Vec:
        """The averaging window (sums to one, zero ends excluded)."""
        k = scipy.signal.windows.hann(self.window + 2)[1:-1]
        return k / k.sum()


@dataclass(frozen=True)
class ArmSeries:
    """The checked signals of one arm recording, rows = samples, columns = joints 1..7."""

    time: Vec
    rate: float
    q: Vec
    tau_J: Vec | None
    """None: no link-side torque sensors (a drive-torque log)."""
    tau_J_d: Vec | None
    """The drive channel: the commanded torque (``drive_measured`` False) or the measured
    drive torque tau_drive (True); None: neither is in the recording."""
    sigma_q: Vec
    sigma_tau: Vec
    sigma_cmd: Vec
    """Noise of the drive channel: the drive's torque ripple about the command, or the
    measured drive torque's own noise."""
    load: Vec | None = None
    """samples x 4: the load the controller was told of (m_load, F_x_Cload1..3), part of the
    nominal model; None when the recording does not log it."""
    drive_measured: bool = False
    """The drive channel is a measured drive torque (tau_drive), not a command (tau_J_d)."""
    breaks: tuple[int, ...] = ()
    """Samples that start a new stretch of the recording (the state restored before them):
    no comparison window reaches across one."""


def _column(rec: Recording, name: str) -> Vec:
    col = rec.signals.column(name)
    if col.null_count:
        raise IdentificationError(f"channel {name} has {col.null_count} missing sample(s): "
                                  "channels of unequal length or gaps; every channel needs "
                                  f"all {rec.signals.num_rows} samples")
    x = col.to_numpy().astype(float)
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise IdentificationError(f"channel {name} has {bad.size} non-finite sample(s) (NaN/inf), "
                                  f"first at row {bad[0]}")
    return x


def _sigmas(rec: Recording, names: tuple[str, ...], default: Vec | None) -> Vec:
    got = rec.meta.noise_sigma
    if default is None and any(n not in got for n in names):
        missing = [n for n in names if n not in got]
        raise IdentificationError(f"meta.json noise_sigma lacks {', '.join(missing)}: the "
                                  "diagnosis judges 'beyond noise' against it")
    s = np.array([float(got.get(n, np.nan)) for n in names])
    if default is not None:
        s = np.where(np.isfinite(s), s, default)
    if np.any(~np.isfinite(s)) or np.any(s < 0):
        raise IdentificationError(f"noise_sigma of {names[0]}..{names[-1]} must be finite and >= 0, got {s}")
    return s


def _family(rec: Recording, cols: set[str], prefix: str, n: int) -> Vec | None:
    """The n channels prefix1..n, None when none is in the recording; one line when some are."""
    names = ch.numbered(prefix, n)
    present = [c for c in names if c in cols]
    if not present:
        return None
    if len(present) < n:
        missing = [c for c in names if c not in cols]
        raise IdentificationError(f"the recording has {', '.join(present)} but not "
                                  f"{', '.join(missing)}: give {prefix} of all {n} joints or none")
    return np.column_stack([_column(rec, c) for c in names])


def _joint_count(cols: set[str]) -> int:
    k = 0
    while f"q{k + 1}" in cols:
        k += 1
    return k


def read_arm_series(rec: Recording, arm: ArmModel = PANDA_ARM, breaks_allowed: bool = False
                    ) -> ArmSeries:
    """The arm signals of `rec` for ``arm``, or IdentificationError naming what is wrong with
    them. noise_sigma must give q and the measured torques; tau_J_d's (the drive's torque
    ripple about the command) defaults to tau_J's when the recording does not state it.
    ``breaks_allowed``: a gap of whole missed periods starts a new stretch (an episode's state
    restore, tasks/episode_recorder.py) instead of being refused."""
    cols = set(rec.signals.column_names)
    n = arm.n
    q_names = ch.numbered("q", n)
    missing = [c for c in ("time",) + q_names if c not in cols]
    if missing:
        raise IdentificationError(f"the arm-dynamics diagnosis of {arm.name} ({n} joints) needs "
                                  f"channels {', '.join(missing)}, not in the recording")
    if f"q{n + 1}" in cols:
        raise IdentificationError(f"the recording has {_joint_count(cols)} joints (q1..q"
                                  f"{_joint_count(cols)}), the robot {arm.name} has {n}"
                                  + ("" if arm.source != "built-in" else
                                     "; give the arm's model file with --robot FILE"))
    t = _column(rec, "time")
    if t.size < 3 or np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 1 if t.size >= 2 else 0
        raise IdentificationError(f"time must increase strictly (row {bad} repeats or goes back)")
    rate = float(rec.meta.sample_rate_hz)
    ticks = np.diff(t) * rate
    gap = (np.abs(ticks - np.round(ticks)) <= RATE_TOLERANCE) & (np.round(ticks) >= 2)
    breaks = tuple(int(i) + 1 for i in np.flatnonzero(gap)) if breaks_allowed else ()
    off = np.abs(ticks - 1.0) > RATE_TOLERANCE
    if breaks_allowed:
        off &= ~gap
    if np.any(off):
        dt = np.diff(t)
        worst = int(np.argmax(np.where(off, np.abs(ticks - 1.0), -1.0)))
        raise IdentificationError(f"samples are not uniform at {rate:g} Hz (interval {dt[worst]:.6g} s "
                                  f"at row {worst + 1}); put them on the grid with `serpar import "
                                  f"FILE --rate {rate:g}` (jitter and missed ticks repaired, counted)")
    q = np.column_stack([_column(rec, c) for c in q_names])
    lo, hi = np.asarray(arm.q_min) - Q_MARGIN, np.asarray(arm.q_max) + Q_MARGIN
    outside = np.flatnonzero(np.any((q < lo) | (q > hi), axis=0))
    if outside.size:
        j = int(outside[0])
        raise IdentificationError(f"q{j + 1} reaches {q[:, j].min():.3g}..{q[:, j].max():.3g}, outside "
                                  f"{arm.name}'s range {arm.q_min[j]:.4g}..{arm.q_max[j]:.4g} rad: "
                                  "degrees, motor-side angles, or another robot?")
    tau = _family(rec, cols, "tau_J", n)
    command = _family(rec, cols, "tau_J_d", n)
    drive = _family(rec, cols, DRIVE_PREFIX, n)
    if tau is None and drive is None:
        raise IdentificationError(f"the arm-dynamics diagnosis needs measured torques: tau_J1..{n}"
                                  f" (link-side torque sensors) or {DRIVE_PREFIX}1..{n} (drive "
                                  "torque from motor currents); the recording has neither")
    if command is not None and drive is not None:
        raise IdentificationError(f"the recording has both tau_J_d1..{n} (commanded) and "
                                  f"{DRIVE_PREFIX}1..{n} (measured drive torque); give one of them")
    measured = drive is not None
    names_link, names_drive = ch.numbered("tau_J", n), ch.numbered(
        DRIVE_PREFIX if measured else "tau_J_d", n)
    sigma_tau = _sigmas(rec, names_link, None) if tau is not None else np.full(n, np.nan)
    sigma_drive = _sigmas(rec, names_drive, None if measured or tau is None else sigma_tau)
    for names, sigma in ((names_link, sigma_tau), (names_drive, sigma_drive)):
        zero = [nm for nm, s in zip(names, sigma) if s == 0]
        if zero:  # the torques' misfit is judged in units of their sigma
            raise IdentificationError(f"noise_sigma of {', '.join(zero)} is 0: the diagnosis "
                                      "judges the torque misfit against it; state the "
                                      "sensor's noise (> 0)")
    return ArmSeries(t, rate, q, tau, drive if measured else command, _sigmas(rec, q_names, None),
                     sigma_tau, sigma_drive, _load(rec, cols) if arm.is_panda else None,
                     drive_measured=measured, breaks=breaks)


def _load(rec: Recording, cols: set[str]) -> Vec | None:
    """The declared load (libfranka m_load, F_x_Cload) per sample, or None when not logged."""
    names = (ch.M_LOAD, *ch.F_X_CLOAD)
    present = [c for c in names if c in cols]
    if not present:
        return None
    if len(present) < len(names):
        raise IdentificationError(f"the load has {', '.join(present)} but not "
                                  f"{', '.join(c for c in names if c not in cols)}: give m_load "
                                  "and F_x_Cload1..3 together (libfranka's load) or none")
    load = np.column_stack([_column(rec, c) for c in names])
    if np.any(load[:, 0] < 0):
        raise IdentificationError(f"m_load is negative at row {int(np.argmax(load[:, 0] < 0))}: a mass is >= 0")
    return load


@dataclass(frozen=True)
class Rows:
    """The comparison rows: window centres, one window apart, each window inside the data."""

    centre: NDArray[np.int64]
    kernel: Vec

    @classmethod
    def of(cls, n_samples: int, cfg: SmoothingConfig, breaks: tuple[int, ...] = (),
           clear_after_break: int = 0) -> Rows:
        """One row every window within each stretch between ``breaks``, the first of a stretch
        after a break ``clear_after_break`` samples later than at the recording's start."""
        w = cfg.window
        # the full-rate model needs samples k-1..k+1 and the link sample's half-period shift
        first = w // 2 + 2
        edges = [0, *breaks, n_samples]
        centre = np.concatenate([
            np.arange(lo + first + (clear_after_break if k else 0), hi - w // 2 - 2, w, dtype=np.int64)
            for k, (lo, hi) in enumerate(itertools.pairwise(edges))])
        if centre.size < MIN_ROWS:
            raise IdentificationError(f"{n_samples} samples give {centre.size} windows of {w}; the "
                                      f"diagnosis needs >= {MIN_ROWS} (a recording of >= "
                                      f"{(MIN_ROWS + 1) * w} samples)")
        return cls(centre, cfg.kernel())

    @property
    def half(self) -> int:
        return len(self.kernel) // 2

    def at(self, x: Vec) -> Vec:
        """Kernel-weighted mean of the full-rate series `x` (samples x ...) at every row."""
        idx = self.centre[:, None] + np.arange(-self.half, self.half + 1)[None, :]
        return np.einsum("rm...,m->r...", x[idx], self.kernel)

    def link_at(self, x: Vec) -> Vec:
        """Window mean of x at each row, x first moved half a sample back (period mean)."""
        return self.at(half_sample_back(x))


def half_sample_back(x: Vec) -> Vec:
    """The full-rate series x moved half a sample back: the mean of each sample and the one
    before (the link-side sensor's period mean); the first sample kept."""
    shifted = np.empty_like(x)
    shifted[1:] = 0.5 * (x[1:] + x[:-1])
    shifted[0] = x[0]
    return shifted


def windowed_spline(rows: Rows, x: Vec, link: bool = False) -> BSpline:
    """A cubic spline through the window mean of the full-rate series ``x`` at every sample
    (``link``: moved half a sample back first, as :meth:`Rows.link_at`), in samples: read at a
    row's centre it is that row's windowed value, and between samples it shifts the window by a
    fraction of a sample (a lag or a delay)."""
    windowed = correlate1d(half_sample_back(x) if link else x, rows.kernel, axis=0,
                           mode="nearest")
    return make_interp_spline(np.arange(len(windowed), dtype=float), windowed, k=3)


def full_rate_derivatives(q: Vec, rate: float) -> tuple[Vec, Vec]:
    """Central first and second differences of q at every sample (ends repeated): the
    unsmoothed velocity and acceleration the model is evaluated with before averaging."""
    v, a = np.empty_like(q), np.empty_like(q)
    v[1:-1] = (q[2:] - q[:-2]) * (rate / 2)
    a[1:-1] = (q[2:] - 2 * q[1:-1] + q[:-2]) * rate**2
    v[0], v[-1], a[0], a[-1] = v[1], v[-2], a[1], a[-2]
    return v, a


def noise_gains(kernel: Vec, rate: float) -> tuple[float, float, float]:
    """How white noise of unit sigma comes out of a row: (a measured torque sample; the drive's
    ripple, held per period, so its continuous mean at a sample is that of two periods; the
    acceleration from unit encoder noise [rad/s² per rad], a second difference)."""
    ripple = np.convolve(kernel, [0.5, 0.5])
    acc = np.convolve(kernel, [1.0, -2.0, 1.0]) * rate**2
    return float(np.linalg.norm(kernel)), float(np.linalg.norm(ripple)), float(np.linalg.norm(acc))
