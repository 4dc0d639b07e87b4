"""Shared by the blind-identification tests: run a fixed, seeded set of concealed trials."""

from __future__ import annotations

from collections.abc import Callable, Mapping

from identify.diagnosis.choose import family_from_recording
from identify.diagnosis.select import diagnose

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
