"""The empirical basis library of a Stewart campaign (diagnosis/empirical.py): one leg at a
time longer than the model by a shape in time or in its own stroke, carried to the platform
pose through the exact leg Jacobian (the encoder-offset column of stewart_family.py).

- drift in time: linear, or saturating 1 - exp(-t / tau) (a leg warming to a new steady
  state), one leg at a time: the library's thermal growth is the same for all six;
- proportional to the leg's stroke (from the encoder zero): an encoder scale or screw-lead
  error of one leg; the library's leg-length errors are constants.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.empirical import BasisGroup, Tuning
from serpar.diagnosis.stewart_effects import ENCODER, N_LEGS

if TYPE_CHECKING:
    from serpar.diagnosis.stewart_family import StewartFamily

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]

DRIFT_TAUS = (1 / 24, 1 / 12, 1 / 6, 1 / 3, 2 / 3)
"""Time constants of the saturating drifts, as shares of the campaign's length."""
DRIFT_BOUNDS = (1 / 50, 2.0)
"""A selected drift's time constant is refined within these shares of the campaign: faster
is a step at its start, slower a linear drift."""


def stewart_library(fam: StewartFamily, l_min: float) -> list[BasisGroup]:
    """Per leg: drifts in time (the saturating ones refined in their time constant once
    selected) and a share of its stroke."""
    h = fam.h
    span = max(fam.duration_s, 1e-9)
    t = h.time - h.time.min()
    # the model's whitened prediction per metre of each leg longer: the encoder-offset column
    # (d residual / d offset = d prediction / d length), at every hold once
    every = np.arange(fam.n_samples)
    jac = fam.jacobian({ENCODER: np.zeros(N_LEGS)}, every).reshape(len(every), 6, N_LEGS)

    def longer(name: str, leg: int, variable: str, shape: str, label: str, profile: Vec,
               detail: dict[str, float] | None = None, tuning: Tuning | None = None
               ) -> BasisGroup:
        def columns(rows: Rows) -> Vec:
            rows = np.asarray(rows, np.int64)
            return (jac[rows, :, leg] * profile[rows, None]).reshape(-1, 1)

        def physical(rows: Rows) -> Vec:
            return profile[np.asarray(rows, np.int64), None]
        return BasisGroup(name, variable, shape, label, "m", columns, physical,
                          detail=detail or {}, tuning=tuning)

    def warming(name: str, leg: int, tau: float) -> BasisGroup:
        return longer(name, leg, "time", "drift", f"1 - exp(-t / {tau:.4g} s)",
                      1.0 - np.exp(-t / tau), {"tau_s": tau},
                      Tuning("tau_s", DRIFT_BOUNDS[0] * span, DRIFT_BOUNDS[1] * span,
                             lambda x: warming(name, leg, x)))

    out = []
    for leg in range(N_LEGS):
        name = f"leg {leg + 1}"
        out.append(longer(name, leg, "time", "drift", "linear", t / span))
        out += [warming(name, leg, tau * span) for tau in DRIFT_TAUS]
        out.append(longer(name, leg, f"stroke {leg + 1}", "proportional", "stroke [m]",
                          h.legs[:, leg] - l_min))
    return out
