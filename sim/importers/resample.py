"""The spec's conversions on the uniform grid: ``rate`` (anti-aliased decimation to the output
rate) and ``sigma_from_rest`` (each channel's noise sigma from a rest segment of the output).

Decimation: an integer factor q = source rate / output rate only (a fractional one would
interpolate new samples between the measured ones; refused, the nearest integer factors named).
The filter is a linear-phase FIR (Kaiser window, beta 8, 40 q + 1 taps, cutoff at 0.8 of the
output's Nyquist frequency: flat within 1e-4 to 0.6 of it, below -80 dB from it on, so
nothing aliases), applied with zero phase by ``scipy.signal.resample_poly``. The edges are
extended by point reflection about the first and last samples, which keeps a smooth signal's
value and slope there (zero padding would pull the end samples towards 0): a 3 Hz sine comes
through within 1e-6 to the last sample. What the edge sample holds above the output band (noise,
a tone) is taken as its value, though, and leaks into the first and last 20 output samples (the
filter's half-length): a 0.1 tone at 2 kHz is gone from the interior but puts up to 0.096 on the
first sample (tests/test_import_spec.py). Text channels keep every q-th sample."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy.signal import firwin, resample_poly

from serpar.errors import ConfigError
from serpar.sim.channels import arm_joint
from serpar.sim.importers.spec import ImportSpec, compact

TAPS_PER_FACTOR = 40
CUTOFF = 0.8
"""The filter's -6 dB point as a fraction of the output's Nyquist frequency."""
KAISER_BETA = 8.0
RATIO_TOLERANCE = 1e-6
UNIFORM = 1e-3
"""Stamps within this fraction of a period of a uniform grid (as grid.py)."""
REST_MOTION_RAD = 1e-3
"""A joint whose angle moves more than this over the rest segment (and more than
REST_NOISE_FACTOR times its sample-to-sample noise) is not at rest."""
REST_NOISE_FACTOR = 10.0
MIN_REST_SAMPLES = 10
CONSTANT = 1e-12
"""A sigma below this fraction of the channel's magnitude: the channel does not change over
the segment (its noise is below the data's resolution)."""


def _where(spec: ImportSpec) -> str:
    return Path(spec.path).name


def decimate(t: NDArray[np.float64], arrays: dict[str, NDArray], rate_in: float,
             spec: ImportSpec) -> tuple[NDArray[np.float64], dict[str, NDArray], float, dict]:
    """(time, arrays, rate) at ``spec.rate``, and what was done (machine-readable)."""
    if spec.rate is None:
        return t, arrays, rate_in, {}
    ratio = rate_in / spec.rate
    factor = round(ratio)
    if ratio < 1 - RATIO_TOLERANCE:
        raise ConfigError(f"{_where(spec)}: rate: {spec.rate:g} Hz is above the source's "
                          f"{rate_in:g} Hz; the output rate is reached by decimation only")
    if abs(ratio - factor) > RATIO_TOLERANCE * ratio:
        lo, hi = math.floor(ratio), math.ceil(ratio)
        raise ConfigError(f"{_where(spec)}: rate: the source's {rate_in:g} Hz / {spec.rate:g} Hz "
                          f"= {ratio:.6g} is not an integer; valid: {rate_in:g}/k for an integer "
                          f"k, the nearest {rate_in / lo:g} Hz (/{lo}) and {rate_in / hi:g} Hz "
                          f"(/{hi})")
    if t.size > 1:
        off = np.abs((t - t[0]) * rate_in - np.arange(t.size))
        if off.max() > UNIFORM:
            raise ConfigError(f"{_where(spec)}: rate: decimation needs samples on a uniform "
                              "grid; these stamps are not (drop --no-grid to put them on it)")
    info = {"rate_in_hz": rate_in, "rate_out_hz": rate_in / factor, "factor": factor}
    if factor == 1:
        return t, arrays, rate_in, info
    taps = firwin(TAPS_PER_FACTOR * factor + 1, CUTOFF / factor, window=("kaiser", KAISER_BETA))
    out = {name: v[::factor] if v.dtype == object else
           resample_poly(v, 1, factor, window=taps, padtype="antireflect")
           for name, v in arrays.items()}
    info["filter"] = (f"FIR, Kaiser beta {KAISER_BETA:g}, {taps.size} taps, cutoff "
                      f"{CUTOFF * rate_in / factor / 2:g} Hz (-6 dB), zero phase "
                      "(scipy.signal.resample_poly), edges point-reflected")
    return t[::factor], out, rate_in / factor, info


def _settles(t: NDArray[np.float64], x: NDArray[np.float64]) -> float | None:
    """The first time from which x stays within REST_MOTION_RAD until the segment's end."""
    hi = np.maximum.accumulate(x[::-1])[::-1]
    lo = np.minimum.accumulate(x[::-1])[::-1]
    still = np.flatnonzero(hi - lo <= REST_MOTION_RAD)
    return float(t[still[0]]) if still.size and still[0] < t.size - MIN_REST_SAMPLES else None


def rest_sigma(t: NDArray[np.float64], arrays: dict[str, NDArray], given: dict[str, float],
               spec: ImportSpec) -> tuple[dict[str, float], list[str], dict]:
    """Noise sigma of every numeric channel not in ``given``: the std of the samples about a
    straight line over the rest segment (ddof 2: the line's two parameters)."""
    if spec.sigma_from_rest is None:
        return {}, [], {}
    t0, t1 = spec.sigma_from_rest
    where = f"{_where(spec)}: sigma_from_rest [{t0:g}, {t1:g}] s"
    rel = t - t[0]
    period = float(rel[1]) if rel.size > 1 else 0.0
    eps = 1e-6 * period + 1e-12
    if t1 > rel[-1] + period + eps:  # the last sample holds for one period
        raise ConfigError(f"{where} ends after the recording ({rel[-1] + period:.6g} s from "
                          "the first sample)")
    seg = (rel >= t0 - eps) & (rel <= t1 + eps)
    n = int(seg.sum())
    if n < MIN_REST_SAMPLES:
        raise ConfigError(f"{where} holds {n} samples; at least {MIN_REST_SAMPLES} are needed")
    ts = rel[seg]
    sigma: dict[str, float] = {}
    constant = []
    for name, v in arrays.items():
        if name in given or v.dtype == object:
            continue
        x = v[seg]
        arm = arm_joint(name)
        if arm is not None and arm[0] == "q":
            motion = float(np.ptp(x))
            white = float(np.std(np.diff(x))) / math.sqrt(2)
            if motion > REST_MOTION_RAD and motion > REST_NOISE_FACTOR * white:
                settle = _settles(ts, x)
                hint = (f"; it stays within {REST_MOTION_RAD * 1e3:g} mrad from {settle:.3g} s"
                        if settle is not None else "")
                raise ConfigError(f"{where}: joint {name} is not at rest there: it moves "
                                  f"{motion * 1e3:.3g} mrad peak to peak (more than "
                                  f"{REST_MOTION_RAD * 1e3:g} mrad and {REST_NOISE_FACTOR:g}x "
                                  f"its sample-to-sample noise){hint}")
        line = np.polyval(np.polyfit(ts - ts.mean(), x, 1), ts - ts.mean())
        s = float(np.sqrt(np.sum((x - line) ** 2) / (n - 2)))
        if s <= CONSTANT * max(1.0, float(np.max(np.abs(x)))):
            constant.append(name)
        else:
            sigma[name] = s
    notes = []
    if sigma:
        notes.append(f"sigma of {compact(list(sigma))} from the rest segment {t0:g}-{t1:g} s "
                     f"({n} samples, std about a straight-line fit)")
    if constant:
        notes.append(f"{compact(constant)}: constant over the rest segment, no sigma written "
                     "(the noise is below the data's resolution); give it with --sigma")
    if given:
        notes.append(f"sigma of {compact(list(given))} as given by --sigma")
    info = {"segment_s": [t0, t1], "samples": n, "sigma": sigma, "constant": constant,
            "given": sorted(given)}
    return sigma, notes, info
