""""A or B: these data cannot tell": an established effect whose place another candidate takes
as well is not a finding.

Screen: the candidates that earned their parameters at some selection step, removing there at
least :data:`SCREEN` of what the effect removed at its own step (the scores the forward
selection kept: no extra fit; any step, not only the effect's own, so that the path a split
took does not decide which rivals are tested). Test: the final model with the rival in the effect's
place against the final model, both fitted on each resampling fold's training rows and
compared on its held-out rows (every row is held out once), by Vuong's test for non-nested
models: per row the difference of the two whitened squared residuals, its mean over its
standard error (a rival the main split's held-out rows already leave far behind is not
cross-validated). Below :data:`RIVAL_Z` the data do not prefer the effect over the rival
(and a rival that fits better outright is no less a reason): neither is established.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit, fit_model
from serpar.diagnosis.parallel import results, run_all
from serpar.diagnosis.result import CandidateScore
from serpar.diagnosis.stability import fit_identified

SCREEN = 0.5
"""A rival must have removed at least this share of the effect's held-out chi-square drop at
the step the effect was added."""
RIVAL_Z = 3.0
"""Vuong's statistic below which the held-out rows do not tell the two models apart."""
PRESCREEN = 2.0
"""A rival the main split's held-out rows alone leave behind by this many times RIVAL_Z is
not cross-validated (one fit instead of one per fold)."""
MAX_TESTED = 3
"""Rivals tested per effect, the screen's strongest first."""


@dataclass(frozen=True)
class Rival:
    effect: str
    rival: str
    rival_summary: str
    z: float
    """Vuong's statistic: the held-out evidence for the effect over the rival (sigma)."""

    def words(self) -> str:
        return (f"{self.effect} or {self.rival} ({self.rival_summary}): these data cannot tell "
                f"(the model with {self.rival} in its place fits the rows it did not see "
                f"{'as well' if self.z > 0 else 'better'}, every row held out once: Vuong z = "
                f"{self.z:.1f}, "
                f"< {RIVAL_Z:g})")


def vuong_z(r_a: NDArray[np.float64], r_b: NDArray[np.float64], n_rows: int) -> float:
    """Evidence for model a over model b from their whitened held-out residuals (row-major,
    ``n_rows`` rows of equal length; a residual of another length, with entries beside the
    rows', is taken entry by entry): mean difference of the squared residuals over its
    standard error (positive: a fits better)."""
    return _z(_row_terms(r_a, r_b, n_rows))


def _row_terms(r_a: NDArray[np.float64], r_b: NDArray[np.float64],
               n_rows: int) -> NDArray[np.float64]:
    """Per held-out row, b's squared whitened residual minus a's (entry by entry where the
    residual holds entries beside the rows')."""
    d = r_b**2 - r_a**2
    if n_rows > 0 and d.size % n_rows == 0:  # a row's entries share its noise: one term a row
        d = d.reshape(n_rows, -1).sum(axis=1)
    return d


def rivals(family: Family, kept: Fit, path: list[Fit], scores: list[CandidateScore],
           fixed: Mapping[str, Effect], train: NDArray[np.int64], heldout: NDArray[np.int64],
           splits: list[tuple[NDArray[np.int64], NDArray[np.int64]]] | None = None,
           workers: int = 0) -> dict[str, Rival]:
    """Per established effect of ``kept``, the first rival the held-out rows cannot tell from
    it (none: absent). ``splits``: the resampling folds; each row is held out in one of them,
    so the test is cross-validated over every row (the main split's held-out rows alone made
    the answer depend on which rows the seed held out). Without folds: the main split.
    ``workers``: processes that fit the folds side by side (diagnosis/parallel.py)."""
    pairs = list(splits) if splits else [(train, heldout)]
    step_of = {fit.active[-1]: step for step, fit in enumerate(path) if step}
    summary = {e.name: e.summary for e in family.effects}
    kept_on: list[NDArray[np.float64]] = []  # the kept model's held-out residual per split
    out: dict[str, Rival] = {}
    for name in kept.active:
        step = step_of.get(name)
        mine = next((s for s in scores if s.step == step and s.effect == name), None)
        if mine is None or mine.delta_chi2_heldout <= 0:
            continue
        best: dict[str, float] = {}  # each other candidate's largest earned drop, any step
        for c in scores:
            if c.earns and c.effect not in kept.active:
                best[c.effect] = max(best.get(c.effect, -np.inf), c.delta_chi2_heldout)
        screened = sorted((e for e, drop in best.items()
                           if drop >= SCREEN * mine.delta_chi2_heldout), key=lambda e: -best[e])
        base_r = family.residual(kept.params, heldout)
        for rival in screened[:MAX_TESTED]:
            active = tuple(rival if a == name else a for a in kept.active)
            start = {k: v for k, v in kept.params.items() if k != name}
            try:
                # the main split first: a rival it leaves far behind is not one (one fit)
                swap, _ = fit_identified(family, active, train, heldout, start, fixed)
                if vuong_z(base_r, family.residual(swap.params, heldout),
                           len(heldout)) >= PRESCREEN * RIVAL_Z:
                    continue
                if not kept_on:
                    kept_on = [family.residual(f.params, he) for f, (_, he) in zip(results(
                        run_all([partial(fit_model, family, kept.active, tr, he, kept.params,
                                         fixed) for tr, he in pairs], workers)), pairs)]
                folds = results(run_all([partial(fit_identified, family, active, tr, he,
                                                 swap.params, fixed) for tr, he in pairs],
                                        workers))
                terms = [_row_terms(r_kept, family.residual(fold.params, he), len(he))
                         for (_, he), r_kept, (fold, _) in zip(pairs, kept_on, folds)]
            except (np.linalg.LinAlgError, ValueError):
                continue
            z = _z(np.concatenate(terms))
            if z < RIVAL_Z:
                out[name] = Rival(name, rival, summary.get(rival, rival), z)
                break
    return out


def _z(d: NDArray[np.float64]) -> float:
    spread = float(np.std(d, ddof=1)) if d.size > 1 else 0.0
    if spread == 0.0:
        return 0.0 if not np.any(d) else float(np.sign(d.sum()) * np.inf)
    return float(d.mean() / (spread / np.sqrt(d.size)))
