"""Contact friction in the insertion phase, seen where an episode's signals can show it: the
chamfer slide.

When a journal lands off-centre it slides down a 45 deg chamfer (the bore's entry chamfer on
its tip chamfer's edge, or the reverse: both are 45 deg). Quasi-statically the contact force
on the journal is then the normal N (up and towards the bore axis) plus sliding friction mu N
along the surface, so the lateral and axial parts of the wrench on the hand keep the ratio

    lateral / axial = (1 - mu) / (1 + mu)        (mu = 0.2: 0.667; mu = 0.5: 0.333)

whatever the push. The controller's wrench estimate (``O_F_ext_hat_K``, from the link-side
torque sensors) sees it: on recorded episodes of the default cell its segment means agree with
the simulator's contact force to 0.01-0.06 in the ratio. Below the chamfer the journal chatters
against the bore wall in single 0.1 ms contacts that the 1 kHz, low-passed estimate does not
resolve, and the shoulder landing sticks: neither gives a sliding ratio, so neither is used.

One row per insertion with a chamfer slide: the segment where the tip is between
:data:`WINDOW_M` above the seated height and the estimate exceeds :data:`CONTACT_N`. Its noise
is the estimate's own, measured in the same insert phase before contact (its scatter and its
correlation time), plus :data:`MODEL_RATIO_SIGMA` for what the quasi-static model leaves out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.family import Effect
from serpar.sim import channels as ch
from serpar.sim.physics import PhysicsConfig
from serpar.sim.recording import Recording

Vec = NDArray[np.float64]

NAME = "contact_friction"
EFFECT = Effect(NAME, "journal/bore sliding friction in the insertion (chamfer slide)",
                ("d_mu",), ("1",), np.zeros(1), np.array([-0.19]), np.array([1.0]),
                physical_lower=True)
"""The candidate: the friction coefficient's error against the nominal cell's."""
NOMINAL_MU = PhysicsConfig().precision_friction
CHANNELS = (ch.TCP_POSITION[2], *ch.F_EXT[:3])
WINDOW_M = (1.40e-3, 1.80e-3)
"""Tip height above its seated height during the chamfer slide: journal length 1.5 mm, tip and
entry chamfers 0.1 mm each (sim/conductor.py, sim/baseplate.py), with 0.1 mm either side."""
PRE_CONTACT_M = 2.0e-3
"""Samples of the insert phase this far above the seat are the approach: no contact."""
CONTACT_N = 0.4
"""|estimate| above this is contact (about 20x the momentum observer's noise per axis at rest)."""
SEATED_N = 2.0
"""The insertion ended seated when the axial estimate of its last 0.1 s exceeds this."""
MIN_SLIDE = 20
"""Fewest samples (ms) of a chamfer slide."""
MODEL_RATIO_SIGMA = 0.07
"""The quasi-static ratio's own error: the simulator's contact force on four recorded slides
at mu = 0.2 gave ratios 0.68-0.78 against 0.667 (RMS 0.07)."""


@dataclass(frozen=True)
class ChamferSlides:
    """One row per chamfer slide: mean lateral and axial estimate [N] and their noise."""

    time: Vec
    lateral: Vec
    axial: Vec
    sigma_lateral: Vec
    sigma_axial: Vec
    samples: NDArray[np.int64]
    not_used: dict[str, int]
    """Insert phases without a usable slide, by reason."""

    @property
    def n(self) -> int:
        return len(self.time)

    def residual(self, d_mu: Vec | None, rows: NDArray[np.int64]) -> Vec:
        """(lateral - g axial) / its sigma: zero when the slide's force ratio is the model's."""
        g = self._ratio(d_mu)
        return (self.lateral[rows] - g * self.axial[rows]) / self.sigma(rows, d_mu)

    def sigma(self, rows: NDArray[np.int64], d_mu: Vec | None = None) -> Vec:
        """[N] The noise of lateral - g axial."""
        g = self._ratio(d_mu)
        return np.sqrt(self.sigma_lateral[rows] ** 2 + (g * self.sigma_axial[rows]) ** 2
                       + (MODEL_RATIO_SIGMA * self.axial[rows]) ** 2)

    @staticmethod
    def _ratio(d_mu: Vec | None) -> float:
        mu = NOMINAL_MU + (0.0 if d_mu is None else float(d_mu[0]))
        return (1.0 - mu) / (1.0 + mu)


def _correlation_time(x: Vec, dt: float) -> float:
    """Integral time scale of a noise series (sum of its autocorrelation to the first zero)."""
    x = x - x.mean()
    if x.size < 10 or not np.any(x):
        return dt
    acf = np.correlate(x, x, "full")[x.size - 1:] / (x @ x)
    stop = int(np.argmax(acf <= 0)) or acf.size
    return max(float(acf[:stop].sum()) * dt, dt / 2)


def chamfer_slides(rec: Recording) -> ChamferSlides:
    """The chamfer slides of an episode recording's insert phases (none, with the reason, when
    the recording lacks the wrench estimate or the TCP height)."""
    cols = set(rec.signals.column_names)
    missing = [c for c in CHANNELS if c not in cols]
    if missing:  # the arm's dynamics can still be diagnosed: say why the insertions are not
        n_insert = sum(p.name == "insert" for p in rec.meta.phases)
        return _slides([], {f"no {', '.join(missing)} channel(s)": n_insert})
    t = np.asarray(rec.signals.column("time"), float)
    z = np.asarray(rec.signals.column(ch.TCP_POSITION[2]), float)
    f = np.stack([np.asarray(rec.signals.column(c), float) for c in CHANNELS[1:]], axis=1)
    dt = 1.0 / float(rec.meta.sample_rate_hz)
    rows: list[tuple[float, float, float, float, float, int]] = []
    not_used: dict[str, int] = {}

    def skip(reason: str) -> None:
        not_used[reason] = not_used.get(reason, 0) + 1

    for p in (p for p in rec.meta.phases if p.name == "insert"):
        s = np.flatnonzero((t >= p.start) & (t <= p.end))
        tail = s[-100:]
        if s.size < 300 or f[tail, 2].mean() < SEATED_N:
            skip("not seated")
            continue
        h = z[s] - z[tail].mean()
        pre = s[(h > PRE_CONTACT_M) & (np.arange(s.size) > 50)]
        seg = s[(h > WINDOW_M[0]) & (h < WINDOW_M[1]) & (np.linalg.norm(f[s], axis=1) > CONTACT_N)]
        if seg.size < MIN_SLIDE:
            skip("no chamfer slide (landed within the clearance)")
            continue
        if pre.size < 50:
            skip("no approach to measure the estimate's noise on")
            continue
        direction = f[seg, :2].mean(axis=0)
        direction /= np.linalg.norm(direction)
        lateral, axial = f[seg, :2] @ direction, f[seg, 2]
        span = seg.size * dt
        rows.append((t[seg[0]], lateral.mean(), axial.mean(),
                     sigma_of_mean(f[pre, :2] @ direction, dt, span),
                     sigma_of_mean(f[pre, 2], dt, span), seg.size))
    return _slides(rows, not_used)


def sigma_of_mean(x: Vec, dt: float, span: float) -> float:
    """Sigma of the mean over ``span`` seconds of a series with ``x``'s scatter and correlation
    time: variance sigma^2 * 2 tau / T (at most sigma^2)."""
    return float(x.std() * np.sqrt(min(1.0, 2 * _correlation_time(x, dt) / span)))


def _slides(rows: list[tuple[float, float, float, float, float, int]],
            not_used: dict[str, int]) -> ChamferSlides:
    a = np.array(rows, float).reshape(-1, 6)
    return ChamferSlides(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 4], a[:, 5].astype(np.int64),
                         not_used)
