"""Time series with jittered stamps and missed ticks on a uniform control grid.

A robot's controller samples at its ticks (libfranka: 1 kHz); a log's stamps jitter around
them and some ticks are missing. Each sample goes to its nearest tick of a grid fitted to the
stamps (rate from ``--rate`` or the stamps, phase and drift by least squares); two samples on
one tick keep the one nearer to it; a missed tick is filled by linear interpolation between
its neighbours (text channels: the previous value). Every repair is counted; a gap longer
than MAX_GAP_TICKS is lost data, not jitter, and an error naming where it is."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.sim.recording import RecordingError

MAX_GAP_TICKS = 50
"""Longest run of missed ticks filled by interpolation (50 ms at 1 kHz)."""
UNIFORM = 1e-3
"""Stamps within this fraction of a period of a uniform grid need no repair."""


@dataclass(frozen=True)
class GridRepair:
    rate_hz: float
    samples_in: int
    ticks: int
    filled_ticks: int
    """Missed ticks filled by interpolation."""
    dropped_samples: int
    """Samples on a tick that a nearer sample holds."""
    longest_gap_ticks: int
    max_stamp_offset_s: float
    """Largest |stamp - its tick|: the jitter."""

    @property
    def repaired(self) -> bool:
        return bool(self.filled_ticks or self.dropped_samples
                    or self.max_stamp_offset_s > UNIFORM / self.rate_hz)

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)

    def words(self) -> str:
        return (f"on a {self.rate_hz:g} Hz grid: {self.ticks} ticks from {self.samples_in} "
                f"samples, {self.filled_ticks} missed ticks filled (longest gap "
                f"{self.longest_gap_ticks}), {self.dropped_samples} samples dropped sharing a "
                f"tick, stamps off their ticks by up to {1e3 * self.max_stamp_offset_s:.3g} ms")


def _coherence(t: NDArray[np.float64], periods: NDArray[np.float64]) -> NDArray[np.float64]:
    """|mean exp(2 pi i t / T)| per candidate period T: 1 for stamps on a grid of period T,
    near 0 for the wrong one, a peak still when jitter spreads them (chunked: memory)."""
    out = np.empty(periods.size)
    for a in range(0, periods.size, 256):
        phase = np.exp(2j * np.pi * np.outer(1.0 / periods[a:a + 256], t))
        out[a:a + 256] = np.abs(phase.mean(axis=1))
    return out


def _period(t: NDArray[np.float64]) -> float:
    """The grid's period from the stamps alone. The median interval is within a few % of it,
    but over thousands of ticks that is many ticks of drift; the period at which the stamps
    are most coherent is not, and is found on a growing prefix (each 8x longer, searched
    about the last one's peak), so a long log costs a few hundred candidates per pass."""
    t = t - t[0]
    period = float(np.median(np.diff(t)))
    lo, hi, n = 0.95 * period, 1.05 * period, min(t.size, 2000)
    while True:
        span = max(float(t[n - 1]), period) / period  # ticks in the prefix
        step = 0.02 * period / span  # 0.02 cycles of drift over the prefix
        candidates = np.arange(lo, hi + step, step)
        period = float(candidates[int(np.argmax(_coherence(t[:n], candidates)))])
        if n == t.size:
            return period
        n = min(t.size, 8 * n)
        lo, hi = period - 0.5 * period / span, period + 0.5 * period / span


def _ticks(t: NDArray[np.float64], period: float, fit_rate: bool
           ) -> tuple[NDArray[np.int64], float, float]:
    """Tick index per sample and the grid (origin, period) fitted to the stamps: the phase
    from the stamps' circular mean, then (rate not given) period and phase by least squares."""
    phase = np.angle(np.mean(np.exp(2j * np.pi * (t - t[0]) / period)))
    origin = float(t[0] + phase * period / (2 * np.pi))
    k = np.rint((t - origin) / period).astype(np.int64)
    if fit_rate and np.ptp(k) > 0:
        period, origin = (float(v) for v in np.polyfit(k, t, 1))
        k = np.rint((t - origin) / period).astype(np.int64)
    return k - k.min(), origin + k.min() * period, period


def on_grid(t: NDArray[np.float64], columns: dict[str, NDArray], rate: float | None,
            where: str = "") -> tuple[NDArray[np.float64], dict[str, NDArray], GridRepair]:
    """(grid times, columns on the grid, what was repaired). ``t`` must increase strictly."""
    if rate is not None and not (np.isfinite(rate) and rate > 0):
        raise RecordingError(f"--rate {rate}: a sample rate in Hz, > 0")
    period = 1.0 / rate if rate is not None else _period(t)
    k, origin, period = _ticks(t, period, fit_rate=rate is None)
    offset = np.abs(t - (origin + k * period))
    order = np.lexsort((offset, k))  # per tick, the nearest sample first
    first = np.r_[True, np.diff(k[order]) > 0]
    keep = np.sort(order[first])
    n_ticks = int(k.max()) + 1
    present = np.zeros(n_ticks, bool)
    present[k[keep]] = True
    gaps = np.diff(np.flatnonzero(present)) - 1
    longest = int(gaps.max()) if gaps.size else 0
    if longest > MAX_GAP_TICKS:
        at = int(np.flatnonzero(present)[int(np.argmax(gaps))])
        raise RecordingError(f"{where}: {longest} ticks ({longest * period * 1e3:.4g} ms) missing "
                             f"after t = {origin + at * period:.6g} s, more than {MAX_GAP_TICKS} "
                             "may be filled: lost data; cut the log there or import the parts "
                             "separately")
    grid = origin + np.arange(n_ticks) * period
    kk = k[keep]
    out: dict[str, NDArray] = {}
    for name, v in columns.items():
        v = v[keep]
        if v.dtype == object:
            idx = np.maximum.accumulate(np.where(present, np.arange(n_ticks), 0))
            full = np.empty(n_ticks, object)
            full[kk] = v
            out[name] = full[idx]
        else:
            out[name] = np.interp(np.arange(n_ticks), kk, v)
    repair = GridRepair(1.0 / period, int(t.size), n_ticks, int((~present).sum()),
                        int(t.size - keep.size), longest, float(offset.max()))
    return grid, out, repair
