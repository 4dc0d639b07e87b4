"""Shared by the blind-identification tests: run a fixed, seeded set of concealed trials."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.select import diagnose

RMS_TARGET = 1.5
"""Held-out RMS after the fit, in units of the noise floor (issue 7)."""


def run_trials(make_twin: Callable, trials: Mapping[str, int]) -> dict[str, tuple]:
    """Effect ("none" for none) -> (recording, answer, family, diagnosis) of its twin made with
    the given seed at the default magnitude and diagnosed blind with the same seed."""
    out = {}
    for effect, seed in trials.items():
        rec, answer = make_twin(None if effect == "none" else effect, None, seed)
        family = family_from_recording(rec)
        out[effect] = (rec, answer, family, diagnose(family, seed))
    return out


def assert_jacobian_matches_differences(family, params: dict, rows: np.ndarray, rel_step: float,
                                        min_step: float, rtol: float, floor: float = 0.0) -> None:
    """The family's exact Jacobian against central differences of its residual, column by
    column; atol = rtol * the column's largest entry + floor."""
    jac = family.jacobian(params, rows)
    k = 0
    for name, x in params.items():
        for i in range(x.size):
            h = max(abs(x[i]) * rel_step, min_step)
            up, dn = x.copy(), x.copy()
            up[i] += h
            dn[i] -= h
            num = (family.residual({**params, name: up}, rows)
                   - family.residual({**params, name: dn}, rows)) / (2 * h)
            assert np.allclose(jac[:, k], num, rtol=rtol, atol=rtol * np.abs(num).max() + floor), \
                (name, i)
            k += 1
