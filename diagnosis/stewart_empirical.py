"""The empirical basis library of a Stewart campaign (diagnosis/empirical.py): one leg at a
time longer than the model by a shape in time or in its own stroke, carried to the platform
pose through the exact leg Jacobian (the encoder-offset column of stewart_family.py).

- drift in time: linear, or saturating 1 - exp(-t / tau) (a leg warming to a new steady
  state), one leg at a time: the library's thermal growth is the same for all six;
- proportional to the leg's stroke (from the encoder zero): an encoder scale or screw-lead
  error of one leg; the library's leg-length errors are constants.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.empirical import BasisGroup
from serpar.diagnosis.stewart_effects import ENCODER, N_LEGS

if TYPE_CHECKING:
    from serpar.diagnosis.stewart_family import StewartFamily

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]

DRIFT_TAUS = (1 / 24, 1 / 12, 1 / 6, 1 / 3, 2 / 3)
"""Time constants of the saturating drifts, as shares of the campaign's length."""


def stewart_library(fam: StewartFamily, l_min: float) -> list[BasisGroup]:
    """Per leg: drifts in time and a share of its stroke."""
    h = fam.h
    span = max(fam.duration_s, 1e-9)
    t = h.time - h.time.min()
    profiles = [("linear", t / span)] + [
        (f"1 - exp(-t / {tau * span:.0f} s)", 1.0 - np.exp(-t / (tau * span))) for tau in DRIFT_TAUS]

    def longer(leg: int, shape: Vec) -> tuple[Callable[[Rows], Vec], Callable[[Rows], Vec]]:
        # the model's whitened prediction per metre of leg `leg` longer, times the shape: the
        # encoder-offset column (d residual / d offset = d prediction / d length)
        def columns(rows: Rows) -> Vec:
            rows = np.asarray(rows, np.int64)
            jac = fam.jacobian({ENCODER: np.zeros(N_LEGS)}, rows).reshape(len(rows), 6, N_LEGS)
            return (jac[:, :, leg] * shape[rows, None]).reshape(-1, 1)

        def physical(rows: Rows) -> Vec:
            return shape[np.asarray(rows, np.int64), None]
        return columns, physical

    out = []
    for leg in range(N_LEGS):
        name = f"leg {leg + 1}"
        for label, profile in profiles:
            cols, phys = longer(leg, profile)
            out.append(BasisGroup(name, "time", "drift", label, "m", cols, phys))
        stroke = h.legs[:, leg] - l_min
        cols, phys = longer(leg, stroke)
        out.append(BasisGroup(name, f"stroke {leg + 1}", "proportional", "stroke [m]", "m",
                              cols, phys))
    return out
