""""A or B: these data cannot tell": an established effect whose place another candidate takes
as well is not a finding.

Screen: the candidates that, at the selection step where the effect was added, also earned
their parameters and removed at least :data:`SCREEN` of what it removed (the scores the
forward selection kept: no extra fit). Test: the final model with the rival in the effect's
place, fitted, against the final model on the held-out rows, by Vuong's test for non-nested
models: per held-out row the difference of the two whitened squared residuals, its mean over
its standard error. Below :data:`RIVAL_Z` the data do not prefer the effect over the rival
(and a rival that fits better outright is no less a reason): neither is established.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit
from serpar.diagnosis.result import CandidateScore
from serpar.diagnosis.stability import fit_identified

SCREEN = 0.5
"""A rival must have removed at least this share of the effect's held-out chi-square drop at
the step the effect was added."""
RIVAL_Z = 3.0
"""Vuong's statistic below which the held-out rows do not tell the two models apart."""


@dataclass(frozen=True)
class Rival:
    effect: str
    rival: str
    rival_summary: str
    z: float
    """Vuong's statistic: the held-out evidence for the effect over the rival (sigma)."""

    def words(self) -> str:
        return (f"{self.effect} or {self.rival} ({self.rival_summary}): these data cannot tell "
                f"(the model with {self.rival} in its place fits the held-out rows "
                f"{'as well' if self.z > 0 else 'better'}: Vuong z = {self.z:.1f}, "
                f"< {RIVAL_Z:g})")


def vuong_z(r_a: NDArray[np.float64], r_b: NDArray[np.float64], n_rows: int) -> float:
    """Evidence for model a over model b from their whitened held-out residuals (rows of
    equal length, row-major): mean per-row difference of the squared residuals over its
    standard error (positive: a fits better)."""
    d = (r_b**2 - r_a**2).reshape(n_rows, -1).sum(axis=1)
    spread = float(np.std(d, ddof=1)) if n_rows > 1 else 0.0
    if spread == 0.0:
        return 0.0 if not np.any(d) else float(np.sign(d.sum()) * np.inf)
    return float(d.mean() / (spread / np.sqrt(n_rows)))


def rivals(family: Family, kept: Fit, path: list[Fit], scores: list[CandidateScore],
           fixed: Mapping[str, Effect], train: NDArray[np.int64], heldout: NDArray[np.int64]
           ) -> dict[str, Rival]:
    """Per established effect of ``kept``, the first rival the held-out rows cannot tell from
    it (none: absent)."""
    step_of = {fit.active[-1]: step for step, fit in enumerate(path) if step}
    summary = {e.name: e.summary for e in family.effects}
    base_r = family.residual(kept.params, heldout)
    out: dict[str, Rival] = {}
    for name in kept.active:
        step = step_of.get(name)
        mine = next((s for s in scores if s.step == step and s.effect == name), None)
        if mine is None or mine.delta_chi2_heldout <= 0:
            continue
        screened = sorted((s for s in scores if s.step == step and s.earns
                           and s.effect not in kept.active
                           and s.delta_chi2_heldout >= SCREEN * mine.delta_chi2_heldout),
                          key=lambda s: -s.delta_chi2_heldout)
        for s in screened:
            active = tuple(s.effect if a == name else a for a in kept.active)
            start = {k: v for k, v in kept.params.items() if k != name}
            try:
                swap, _ = fit_identified(family, active, train, heldout, start, fixed)
            except (np.linalg.LinAlgError, ValueError):
                continue
            z = vuong_z(base_r, family.residual(swap.params, heldout), len(heldout))
            if z < RIVAL_Z:
                out[name] = Rival(name, s.effect, summary.get(s.effect, s.effect), z)
                break
    return out
