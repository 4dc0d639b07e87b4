"""The diagnosis engine: locate -> hypothesise -> fit -> select -> report, as staged pure
functions over a :class:`~serpar.diagnosis.family.Family`.

Selection rule (forward selection, one effect per step). At each step every candidate not yet
in the model is fitted together with the current model on the training rows (scipy
``least_squares``) and scored on the held-out rows. A candidate with k parameters *earns its
parameters* when it lowers the information criterion on both splits:

    training:  chi^2 drop > k ln(n_train)     (BIC with the recording's noise model)
    held-out:  chi^2 drop > k ln(n_heldout)   (the same price, paid on data the fit never saw)

Of the candidates that earn, the one with the lowest held-out chi-square is added. Selection
stops when none earns, or when the held-out residual has reached the noise floor (its
chi-square test against unit-variance noise gives p >= ``alpha``). If the baseline alone is
at the noise floor on held-out data the answer is literally "no missing physics found
beyond noise".
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from serpar.diagnosis.family import Family
from serpar.diagnosis.fit import Fit, blocks_of, fit_model
from serpar.diagnosis.locate import chi2_p
from serpar.diagnosis.result import (
    NO_MISSING_PHYSICS,
    CandidateScore,
    Diagnosis,
    Finding,
    ParamEstimate,
)
from serpar.errors import IdentificationError

Progress = Callable[[str], None]


@dataclass(frozen=True)
class SelectConfig:
    alpha: float = 0.01
    """Significance at which the held-out residual is still "beyond noise"."""
    max_effects: int = 3

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise IdentificationError(f"SelectConfig.alpha must be in (0, 1), got {self.alpha}")
        if self.max_effects < 0:
            raise IdentificationError("SelectConfig.max_effects must be >= 0")


def at_noise_floor(fit: Fit, alpha: float) -> bool:
    """Held-out chi-square consistent with noise at significance ``alpha``."""
    if fit.n_heldout == 0:
        return False
    import scipy.stats

    return float(scipy.stats.chi2.sf(fit.heldout_chi2, fit.n_heldout)) >= alpha


def earns(current: Fit, new: Fit) -> tuple[float, float, bool]:
    """(training BIC change, held-out chi^2 drop, whether the extra parameters are earned)."""
    k = new.n_params - current.n_params
    d_bic = new.bic - current.bic
    d_held = current.heldout_chi2 - new.heldout_chi2
    ok = k > 0 and d_bic < 0 and d_held > k * float(np.log(max(new.n_heldout, 2)))
    return d_bic, d_held, ok


def forward_select(family: Family, train: np.ndarray, heldout: np.ndarray,
                   cfg: SelectConfig, report: Progress | None = None
                   ) -> tuple[list[Fit], list[CandidateScore]]:
    """The sequence of fits (baseline first, then one added effect per step) and the score of
    every candidate tried at every step."""
    say = report or (lambda _msg: None)
    say("baseline")
    path = [fit_model(family, (), train, heldout)]
    scores: list[CandidateScore] = []
    step = 0
    while step < cfg.max_effects and not at_noise_floor(path[-1], cfg.alpha):
        step += 1
        current = path[-1]
        best: Fit | None = None
        for effect in family.effects:
            if effect.name in current.active:
                continue
            say(effect.name)
            try:
                new = fit_model(family, current.active + (effect.name,), train, heldout,
                                current.params)
            except (np.linalg.LinAlgError, ValueError) as exc:
                # one candidate that cannot be fitted here is a finding, not a crash
                say(f"{effect.name} failed: {exc}")
                continue
            d_bic, d_held, ok = earns(current, new)
            scores.append(CandidateScore(step, effect.name, effect.n_params, d_bic, d_held,
                                         new.heldout_rms, ok))
            if ok and (best is None or new.heldout_chi2 < best.heldout_chi2):
                best = new
        if best is None:
            break
        path.append(best)
    return path, scores


def _excess(fit: Fit) -> float:
    """Held-out mean square above the noise floor (whitened noise has mean square 1)."""
    return max(fit.heldout_chi2 / max(fit.n_heldout, 1) - 1.0, 0.0)


def _estimates(family: Family, fit: Fit, name: str) -> tuple[ParamEstimate, ...]:
    block = next(b for b in blocks_of(family, fit.active) if b.name == name)
    return tuple(ParamEstimate(p, float(v), float(s), u) for p, v, s, u in
                 zip(block.param_names, fit.params[name], fit.std[name], block.units))


def diagnose(family: Family, seed: int = 0, cfg: SelectConfig | None = None,
             report: Progress | None = None) -> Diagnosis:
    """Run every stage on one family; the result holds the findings and the evidence."""
    # The fits are small (hundreds of rows, tens of columns): OpenBLAS threads on a shared
    # 2-core machine only wait for each other (a 28-parameter fit: 3.5 s against 0.17 s).
    if cfg is None:
        # a family whose recordings hold several independent parts (an episode: the arm's
        # dynamics and its insertions) may allow more effects; each must still earn its place
        cfg = SelectConfig(max_effects=getattr(family, "max_effects", SelectConfig.max_effects))
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(family, seed, cfg, report)


def _diagnose(family: Family, seed: int, cfg: SelectConfig, report: Progress | None
              ) -> Diagnosis:
    t0 = time.perf_counter()
    train, heldout = family.split(np.random.default_rng(seed))
    train, heldout = np.asarray(train, np.int64), np.asarray(heldout, np.int64)
    if train.size == 0 or heldout.size == 0:
        raise IdentificationError(f"{family.kind}: the split left {train.size} training and "
                                  f"{heldout.size} held-out rows; both must be non-empty")
    if np.intersect1d(train, heldout).size:
        raise IdentificationError(f"{family.kind}: training and held-out rows overlap")
    path, scores = forward_select(family, train, heldout, cfg, report)
    base, final = path[0], path[-1]
    every = np.concatenate([train, heldout])
    before = family.residual(base.params, heldout)
    after = family.residual(final.params, heldout)
    excess0 = _excess(base)
    findings = []
    for rank, (prev, fit) in enumerate(itertools.pairwise(path), start=1):
        name = fit.active[-1]
        share = (_excess(prev) - _excess(fit)) / excess0 if excess0 > 0 else 0.0
        d_bic, d_held, _ = earns(prev, fit)
        summary = next(e.summary for e in family.effects if e.name == name)
        # parameters and uncertainty from the final model (all selected effects together)
        rest = (_excess(prev) - _excess(fit)) / _excess(prev) if _excess(prev) > 0 else 0.0
        findings.append(Finding(rank, name, summary, _estimates(family, final, name),
                                float(np.clip(share, 0.0, 1.0)), d_bic, d_held,
                                float(np.clip(rest, 0.0, 1.0))))
    if len(path) == 1 and at_noise_floor(base, cfg.alpha):
        verdict = NO_MISSING_PHYSICS
    elif len(path) == 1:
        verdict = ("the model misses something beyond noise, but no candidate effect earns "
                   "its parameters on held-out data")
    else:
        verdict = "missing physics: " + ", ".join(f.summary for f in findings)
    baseline = (_estimates(family, final, family.baseline.name)
                if family.baseline is not None else ())
    model = {name: {"values": [float(v) for v in final.params[name]],
                    "std": [float(s) for s in final.std[name]],
                    "names": list(next(b for b in blocks_of(family, final.active)
                                       if b.name == name).param_names)}
             for name in final.params}
    explained = (excess0 - _excess(final)) / excess0 if excess0 > 0 else 0.0
    return Diagnosis(
        kind=family.kind, verdict=verdict, findings=tuple(findings), candidates=tuple(scores),
        locate_before=tuple(family.locate(every, family.residual(base.params, every))),
        locate_after=tuple(family.locate(every, family.residual(final.params, every))),
        baseline_params=baseline, n_train_rows=int(train.size),
        n_heldout_rows=int(heldout.size), heldout_rms_before=base.heldout_rms,
        heldout_rms_after=final.heldout_rms, heldout_p_after=chi2_p(after),
        explained=float(np.clip(explained, 0.0, 1.0)), wall_s=time.perf_counter() - t0,
        model={"kind": family.kind, "effects": list(final.active), "params": model},
        heldout_before=before, heldout_after=after, heldout_rows=heldout)
