"""Stage "locate": where a model's whitened residual exceeds the recording's noise.

A group of n whitened residuals is compared with unit-variance Gaussian noise by the
chi-square test (sum of squares ~ chi^2(n)); it is flagged when the p-value is below
``alpha`` divided by the number of groups tested (Bonferroni: a table of 40 groups must not
flag one by chance every other recording) and its RMS is visibly above noise.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.stats
from numpy.typing import NDArray

from serpar.diagnosis.family import LocateRow

ALPHA = 0.01
MIN_RMS = 1.2
"""A group must also exceed noise by 20 % in RMS to be flagged: with thousands of samples the
chi-square test alone flags a noise level that is only a few per cent off."""


def chi2_p(whitened: NDArray[np.float64]) -> float:
    """p-value of sum(w^2) under chi^2(n): the probability noise alone gives this much."""
    w = np.asarray(whitened, float)
    if w.size == 0:
        return 1.0
    return float(scipy.stats.chi2.sf(float(w @ w), w.size))


def locate_rows(groups: Sequence[tuple[str, str, str, NDArray[np.float64]]],
                alpha: float = ALPHA) -> list[LocateRow]:
    """One :class:`LocateRow` per (channel, group, label, whitened residuals) entry."""
    n_tests = max(sum(1 for g in groups if len(g[3])), 1)
    out = []
    for channel, group, label, w in groups:
        w = np.asarray(w, float)
        if w.size == 0:
            continue
        rms = float(np.sqrt(np.mean(w**2)))
        p = chi2_p(w)
        out.append(LocateRow(channel, group, label, int(w.size), rms, p,
                             bool(p < alpha / n_tests and rms > MIN_RMS)))
    return out
