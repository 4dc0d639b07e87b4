"""Stage "what is left": does the held-out residual after the fit pass the noise test, and if
not, is it noise the recording under-states or structure no candidate explains?

The recording states a noise sigma per channel; the whitened residual is measured over that
sigma. Where the data allow, a family estimates the noise itself (``noise_ratio(rows,
whitened)``: the data's noise over the stated sigma, e.g. from the sample-to-sample part of a
time series, which slow physics does not reach). Then

- residual RMS within ``NOISE_MARGIN`` of the estimated noise: the stated sigma is optimistic
  by that ratio, and the residual is noise;
- residual RMS well above the estimated noise: a structured residual remains.

Without an estimate the words say that these data cannot tell the two apart.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.empirical_term import EmpiricalTerm
from serpar.diagnosis.family import Family
from serpar.diagnosis.locate import chi2_p

NOISE_MARGIN = 1.25
"""A residual RMS up to this factor above the data's own noise estimate counts as noise."""
OPTIMISTIC = 1.3
"""A data noise estimate this far above the stated sigma calls the stated sigma optimistic."""


@dataclass(frozen=True)
class ResidualCheck:
    rms: float
    """Held-out whitened RMS after the fit (1 = the stated noise)."""
    p_value: float
    passes: bool
    """The held-out residual passes the chi-square test against the stated noise."""
    noise_ratio: float | None
    """Noise estimated from the data over the stated sigma; None where the data do not allow."""
    noise_method: str
    structured: bool | None
    """A residual well above the data's own noise; None when no noise estimate exists."""
    words: str

    def as_dict(self) -> dict[str, object]:
        return {"heldout_rms_whitened": self.rms, "p_value": self.p_value,
                "passes_noise_test": self.passes, "noise_ratio_estimated": self.noise_ratio,
                "noise_estimate": self.noise_method, "structured": self.structured,
                "words": self.words}


def consecutive_noise_ratio(rows: NDArray[np.int64], whitened: NDArray[np.float64],
                            n_channels: int) -> float | None:
    """sqrt(mean(d^2) / 2) of the differences d between residuals of consecutive rows of the
    same channel: white noise survives differencing, slow structure cancels. None when fewer
    than 50 consecutive pairs exist."""
    rows = np.asarray(rows, np.int64)
    w = np.asarray(whitened, float).reshape(len(rows), n_channels)
    order = np.argsort(rows, kind="stable")
    rows, w = rows[order], w[order]
    pairs = np.flatnonzero(np.diff(rows) == 1)
    if pairs.size < 50:
        return None
    d = w[pairs + 1] - w[pairs]
    return float(np.sqrt(np.mean(d**2) / 2.0))


def check_residual(family: Family, rows: NDArray[np.int64], whitened: NDArray[np.float64],
                   alpha: float) -> ResidualCheck:
    w = np.asarray(whitened, float)
    rms = float(np.sqrt(np.mean(w**2))) if w.size else 0.0
    p = chi2_p(w)
    passes = p >= alpha
    hook = getattr(family, "noise_ratio", None)
    estimate = hook(rows, w) if callable(hook) else None
    ratio, method = estimate if estimate is not None else (None, "")
    structured = None if ratio is None else rms > NOISE_MARGIN * max(ratio, 1.0)
    if passes:
        words = (f"the held-out residual after the fit is consistent with the stated noise "
                 f"(RMS {rms:.2f} x sigma, p = {p:.2g})")
    elif ratio is None:
        words = (f"the held-out residual after the fit is {rms:.2g} x the stated sigma "
                 f"(p = {p:.2g}): physics no candidate covers, or a stated sigma that is too "
                 "small; these data cannot tell which")
    elif not structured and ratio >= OPTIMISTIC:
        words = (f"the held-out residual after the fit ({rms:.2g} x the stated sigma) looks like "
                 f"noise: the data's own noise ({method}) is {ratio:.2g} x the stated sigma, so "
                 f"the stated sigma is optimistic by {ratio:.2g}x; not missing physics")
    elif not structured:
        words = (f"the held-out residual after the fit is {rms:.2g} x the stated sigma, close to "
                 f"the data's own noise ({method}: {ratio:.2g} x): little structure is left")
    else:
        words = (f"a structured residual remains: {rms:.2g} x the stated sigma where the data's "
                 f"own noise ({method}) is {ratio:.2g} x; physics that no candidate explains")
    return ResidualCheck(rms, p, passes, ratio, method, structured, words)


NOISE_EXPLAINED = 0.8
"""An empirical term that takes a noise-like residual's held-out RMS below this share of it
shows structure: a stated sigma too small by a factor cannot be fitted away on held-out data."""


def noise_like_but_explained(residual: ResidualCheck, empirical: EmpiricalTerm
                             ) -> tuple[ResidualCheck, EmpiricalTerm | None]:
    """A residual the noise estimate called noise: structure after all when an empirical term
    explains a material part of it (the estimate was inflated by it); else noise, no term."""
    if not empirical.terms or empirical.heldout_rms_after >= NOISE_EXPLAINED * residual.rms:
        return residual, None
    words = (f"a structured residual remains: {residual.rms:.2g} x the stated sigma; the data's "
             f"own noise estimate ({residual.noise_method}: {residual.noise_ratio:.2g} x) "
             "is inflated by it, since an empirical term removes part of it on held-out data; "
             "physics that no candidate explains")
    return replace(residual, structured=True, words=words), empirical
