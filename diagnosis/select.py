"""The diagnosis engine: locate -> hypothesise -> fit -> select -> report, as staged pure
functions over a :class:`~serpar.diagnosis.family.Family`.

Selection rule (forward selection, one effect per step). At each step every candidate not yet
in the model is fitted together with the current model on the training rows (scipy
``least_squares``) and scored on the held-out rows. A candidate with k parameters *earns its
parameters* when it lowers the information criterion on both splits:

    training:  chi^2 drop > k ln(n_train)     (BIC with the recording's noise model)
    held-out:  chi^2 drop > k ln(n_heldout)   (the same price, paid on data the fit never saw)
    (n: the residual entries the candidate's parameters move, diagnosis/fit.py ``price``)

Of the candidates that earn, the one with the lowest held-out chi-square plus its price
(its held-out price) is added: of two that fit alike, the one with fewer parameters. Selection
stops when none earns, or when the held-out residual has reached the noise floor (its
chi-square test against unit-variance noise gives p >= ``alpha``) in every independent part
of the data the family names (``residual_parts``: an episode's chamfer slides are tested on
their own, or their few rows would be drowned in the arm's thousands). If the baseline alone is
at the noise floor on held-out data the answer is literally "no missing physics found
beyond noise".

Reported values: the split chooses the model and every held-out figure is the training fit's.
Where the model then holds on the held-out rows (their residual passes the noise test, or
looks like noise), the values of the established effects and the baseline (findings, model
file) are fitted on every row, since an estimate from one half has twice the variance; where
a structured residual remains they stay the training fit's.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import scipy.stats
from threadpoolctl import threadpool_limits

from serpar.diagnosis.empirical import characterise
from serpar.diagnosis.empirical_refit import model_refit, outweighed
from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.findings import excess, findings_of, param_estimates, shares, verdict
from serpar.diagnosis.fit import Fit, earns, fit_model
from serpar.diagnosis.locate import chi2_p
from serpar.diagnosis.parallel import run_all
from serpar.diagnosis.reselect import barred_reason, passed_over
from serpar.diagnosis.residual import check_residual, noise_like_but_explained
from serpar.diagnosis.result import CandidateScore, Diagnosis, Finding
from serpar.diagnosis.rivals import rivals
from serpar.diagnosis.stability import (
    N_FOLDS,
    Assessment,
    assess,
    block_of,
    combined_std,
    fit_identified,
    folds,
    release_held,
)
from serpar.diagnosis.units import in_units
from serpar.errors import IdentificationError

Progress = Callable[[str], None]


@dataclass(frozen=True)
class SelectConfig:
    alpha: float = 0.01
    """Significance at which the held-out residual is still "beyond noise"."""
    max_effects: int = 3
    folds: int = N_FOLDS
    """Resampled folds on which a selected effect must hold up (0: no resampling; a selected
    effect then has only to be off its search bounds and material to be reported as found)."""
    workers: int = 0
    """Processes that fit one step's candidates and the folds' models side by side
    (diagnosis/parallel.py; 0: one per core, 1: in this process). The numbers are the same."""

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise IdentificationError(f"SelectConfig.alpha must be in (0, 1), got {self.alpha}")
        if self.max_effects < 0:
            raise IdentificationError("SelectConfig.max_effects must be >= 0")
        if self.workers < 0:
            raise IdentificationError(f"SelectConfig.workers={self.workers}: 0 (every core) "
                                      "or >= 1")
        if self.folds < 0 or self.folds == 1:
            raise IdentificationError(f"SelectConfig.folds={self.folds}: 0 (off) or >= 2")


def at_noise_floor(fit: Fit, alpha: float) -> bool:
    """Held-out chi-square consistent with noise at significance ``alpha``."""
    if fit.n_heldout == 0:
        return False
    return float(scipy.stats.chi2.sf(fit.heldout_chi2, fit.n_heldout)) >= alpha


def beyond_noise(family: Family, fit: Fit, heldout: np.ndarray, alpha: float) -> bool:
    """Whether the held-out residual is beyond noise as a whole or in any of the family's
    independent parts (optional hook ``residual_parts(rows, whitened) -> {name: entries}``)."""
    if not at_noise_floor(fit, alpha):
        return True
    parts = getattr(family, "residual_parts", None)
    if not callable(parts):
        return False
    whitened = family.residual(fit.params, heldout)
    return any(chi2_p(part) < alpha for part in parts(heldout, whitened).values())


Tried = dict[tuple[object, ...], tuple[bool, object]]
"""Candidate fits already made on one split, by what they were fitted from
(:func:`_fit_key`): a second selection (without a barred effect) starts as the first did."""


def _fit_key(active: tuple[str, ...], start: Mapping[str, np.ndarray],
             fixed: Mapping[str, Effect]) -> tuple[object, ...]:
    return (active,
            tuple((k, np.asarray(v, float).tobytes()) for k, v in sorted(start.items())),
            tuple((n, e.fixed, e.param_names, e.x0.tobytes(), e.lower.tobytes(),
                   e.upper.tobytes()) for n, e in sorted(fixed.items())))


def forward_select(family: Family, train: np.ndarray, heldout: np.ndarray,
                   cfg: SelectConfig, report: Progress | None = None,
                   barred: frozenset[str] = frozenset(), tried_before: Tried | None = None
                   ) -> tuple[list[Fit], list[CandidateScore], dict[str, Effect]]:
    """The sequence of fits (baseline first, then one added effect per step), the score of
    every candidate tried at every step, and the selected effects with the parameters the
    data do not identify held at zero (:func:`~serpar.diagnosis.stability.fit_identified`);
    ``barred`` effects are not tried. ``tried_before``: the candidate fits of an earlier
    selection on the same split, reused where a candidate starts from the same model (and
    the fits made here are added to it)."""
    say = report or (lambda _msg: None)
    memo: Tried = {} if tried_before is None else tried_before
    say("baseline")
    if ("baseline",) not in memo:
        memo[("baseline",)] = (True, fit_model(family, (), train, heldout))
    path: list[Fit] = [memo[("baseline",)][1]]  # type: ignore[list-item]
    scores: list[CandidateScore] = []
    fixed: dict[str, Effect] = {}
    took: dict[str, float] = {}  # each candidate's last fit [s]
    step = 0
    while step < cfg.max_effects and beyond_noise(family, path[-1], heldout, cfg.alpha):
        step += 1
        current = path[-1]
        best: tuple[Fit, dict[str, Effect], float] | None = None
        tried = [e for e in family.effects if e.name not in current.active
                 and e.name not in barred]
        held = ", ".join(current.active) or "nothing yet"

        def event(what: str, k: int, step: int = step, held: str = held) -> None:
            if what == "start":
                say(f"step {step} (holding {held}): candidate {k + 1} of {len(tried)}, "
                    f"{tried[k].name}")

        keys = [_fit_key(current.active + (e.name,), current.params, fixed) for e in tried]
        todo = [k for k, key in enumerate(keys) if key not in memo]
        jobs = [partial(fit_identified, family, current.active + (tried[k].name,), train,
                        heldout, current.params, fixed) for k in todo]
        if len(todo) < len(tried):
            say(f"step {step} (holding {held}): {len(tried) - len(todo)} of {len(tried)} "
                "candidates as fitted before")
        # the longest first (as long as the last step took, else by its parameters): a
        # step ends with its slowest fit
        first = sorted(range(len(todo)), key=lambda j: -took.get(
            tried[todo[j]].name, 1e-3 * tried[todo[j]].n_params))
        seconds: dict[int, float] = {}
        for k, outcome in zip(todo, run_all(jobs, cfg.workers,
                                             lambda what, j: event(what, todo[j]), first,
                                             seconds)):
            memo[keys[k]] = outcome
        took.update({tried[todo[j]].name: dt for j, dt in seconds.items()})
        for effect, key in zip(tried, keys):
            ok_fit, got = memo[key]
            if not ok_fit:
                if not isinstance(got, (np.linalg.LinAlgError, ValueError)):
                    raise got
                # one candidate that cannot be fitted here is a finding, not a crash
                say(f"{effect.name} failed: {got}")
                continue
            new, new_fixed = got
            d_bic, d_held, ok = earns(current, new)
            scores.append(CandidateScore(step, effect.name, effect.n_params, d_bic, d_held,
                                         new.heldout_rms, ok))
            # the held-out chi-square with the price of the parameters: where two candidates
            # fit alike, the one with fewer parameters (a relative change of the links' inertia
            # beside their full inertial parameters)
            net = new.heldout_chi2 + new.price_heldout
            if ok and (best is None or net < best[2]):
                best = new, new_fixed, net
        if best is None:
            break
        path.append(best[0])
        fixed = best[1]
    return path, scores, fixed


def default_config(family: Family, workers: int = 0) -> SelectConfig:
    """The selection's defaults for ``family``, on ``workers`` processes (0: every core)."""
    # a family whose recordings hold several independent parts (an episode: the arm's
    # dynamics and its insertions) may allow more effects; each must still earn its place
    return SelectConfig(max_effects=getattr(family, "max_effects", SelectConfig.max_effects),
                        workers=workers)


def diagnose(family: Family, seed: int = 0, cfg: SelectConfig | None = None,
             report: Progress | None = None) -> Diagnosis:
    """Run every stage on one family; the result holds the findings and the evidence."""
    # The fits are small (hundreds of rows, tens of columns): OpenBLAS threads on a shared
    # 2-core machine only wait for each other (a 28-parameter fit: 3.5 s against 0.17 s).
    if cfg is None:
        cfg = default_config(family)
    with threadpool_limits(limits=1, user_api="blas"):
        return _diagnose(family, seed, cfg, report)


def _diagnose(family: Family, seed: int, cfg: SelectConfig, report: Progress | None
              ) -> Diagnosis:
    t0 = time.perf_counter()
    # the folds first: a family's split may set state (episode tare knots) that the final
    # fits below must see from the main split
    splits = folds(family, cfg.folds) if cfg.folds else []
    train, heldout = family.split(np.random.default_rng(seed))
    train, heldout = np.asarray(train, np.int64), np.asarray(heldout, np.int64)
    if train.size == 0 or heldout.size == 0:
        raise IdentificationError(f"{family.kind}: the split left {train.size} training and "
                                  f"{heldout.size} held-out rows; both must be non-empty")
    if np.intersect1d(train, heldout).size:
        raise IdentificationError(f"{family.kind}: training and held-out rows overlap")
    tried: Tried = {}
    sel = _select(family, train, heldout, splits, cfg, report, tried_before=tried)
    failed = [n for n in sel.path[-1].active if n not in sel.kept.active]
    barred = passed_over(sel.path[-1].active, sel.scores, failed)
    set_aside: list[Finding] = []
    if barred:
        if report:
            report(f"selecting again without {', '.join(barred)}")
        again = _select(family, train, heldout, splits, cfg, report, frozenset(barred), tried)
        if again.kept.heldout_rms < sel.kept.heldout_rms:
            first = findings_of(family, sel.path, sel.shares, sel.assessed, sel.fixed, sel.kept, {})
            set_aside = [replace(f, established=False,
                                 reasons=f.reasons + (barred_reason(f.effect, barred[f.effect]),))
                         for f in first if f.effect in barred]
            sel = again
    path, scores, fixed, effect_shares = sel.path, sel.scores, sel.fixed, sel.shares
    base, kept, assessed = path[0], sel.kept, sel.assessed
    demoted: dict[str, tuple[str, ...]] = {}
    every = np.concatenate([train, heldout])
    before = family.residual(base.params, heldout)
    after = family.residual(kept.params, heldout)
    excess0 = excess(base)
    residual = check_residual(family, heldout, after, cfg.alpha)
    empirical = None
    library = getattr(family, "empirical_library", None)
    # tried also on a residual that looks like noise: sharp physics (friction at reversals)
    # inflates the sample-to-sample noise estimate, and only a term that explains part of it
    # tells the two apart (noise_like_but_explained below)
    if callable(library) and not residual.passes:
        if report:
            report("characterising what is left")
        n_channels = after.size // max(heldout.size, 1)
        groups = library()
        empirical = characterise(groups, model_refit(family, kept, fixed, groups, n_channels),
                                 train, heldout, splits, n_channels, every)
        chosen = [groups.index(t.group) for t in empirical.terms]
        stand_ins = outweighed(family, kept, fixed, groups, chosen, n_channels, train, heldout)
        if stand_ins:
            # an established effect that only stood in for the physics the empirical term
            # describes is not a finding: demote it, refit the rest, characterise again
            why = "it no longer earns its parameters once the empirical term is in the model"
            demoted = {name: (why,) for name in stand_ins}
            kept, fixed = fit_identified(family, tuple(a for a in kept.active
                                                       if a not in stand_ins),
                                         train, heldout, kept.params, fixed)
            after = family.residual(kept.params, heldout)
            residual = check_residual(family, heldout, after, cfg.alpha)
            empirical = characterise(groups, model_refit(family, kept, fixed, groups,
                                                         n_channels),
                                     train, heldout, splits, n_channels, every)
    # an effect another candidate replaces as well is "A or B", not a finding; the model keeps
    # it (a model must carry one of the two), and the verdict says which it carries. Only in
    # families that say the test holds there (``tells_rivals``): Vuong's test pools every row
    # and counts no parameters, so a rival that nests the effect (a Stewart geometry's leg
    # lengths hold the encoder offsets) or acts on other rows (an episode's arm against its
    # chamfer slides) reads "alike"
    if kept.active and getattr(family, "tells_rivals", False):
        if report:
            report("rivals")
        for name, rival in rivals(family, kept, path, scores, fixed, train, heldout,
                                  splits, cfg.workers).items():
            demoted[name] = demoted.get(name, ()) + (
                rival.words() + f"; the model carries {name}",)
    if residual.structured is False and empirical is not None:
        residual, empirical = noise_like_but_explained(residual, empirical)
    # the values from every row where the model holds on the rows it never saw: the split
    # chose and scored it (the held-out figures stay the training fit's), and an estimate
    # from half the rows has twice the variance. Where structure is left the model is known
    # to be wrong, and rows it fails on would pull its values toward a compromise.
    adequate = residual.passes or residual.structured is False
    estimate = (fit_model(family, kept.active, np.sort(every), np.zeros(0, np.int64),
                          kept.params, fixed) if adequate else kept)
    found = findings_of(family, path, effect_shares, assessed, fixed, estimate, demoted)
    found += [replace(f, rank=len(found) + k) for k, f in enumerate(set_aside, start=1)]
    # quiet only if no part of the data is beyond noise: the rule selection stops by
    quiet = not beyond_noise(family, base, heldout, cfg.alpha)
    words = verdict(found, quiet, residual.words, empirical)
    baseline = (param_estimates(family.baseline, estimate.params[family.baseline.name],
                                estimate.std[family.baseline.name])
                if family.baseline is not None else ())
    model = {name: {"values": [float(v) for v in estimate.params[name]],
                    "std": [float(s) for s in combined_std(
                        estimate, name, assessed[name].resampled if name in assessed else None)],
                    "names": list(block_of(family, kept.active, name, fixed).param_names)}
             for name in estimate.params}
    explained = (excess0 - excess(kept)) / excess0 if excess0 > 0 else 0.0
    return Diagnosis(
        kind=family.kind, verdict=words, findings=tuple(found), candidates=tuple(scores),
        locate_before=tuple(family.locate(every, family.residual(base.params, every))),
        locate_after=tuple(family.locate(every, family.residual(kept.params, every))),
        baseline_params=baseline, n_train_rows=int(train.size),
        n_heldout_rows=int(heldout.size), heldout_rms_before=base.heldout_rms,
        heldout_rms_after=kept.heldout_rms, heldout_p_after=chi2_p(after),
        explained=float(np.clip(explained, 0.0, 1.0)), wall_s=time.perf_counter() - t0,
        model={"kind": family.kind, "effects": list(kept.active), "params": model,
               **({"empirical": [t.as_dict() for t in empirical.terms]}
                  if empirical is not None and empirical.terms else {})},
        heldout_before=before, heldout_after=after, heldout_rows=heldout, residual=residual,
        empirical=empirical, physical=in_units(family, heldout, before, after),
        not_identifiable=tuple(f"{name} ({why})" for name, why in
                               (getattr(family, "not_identifiable", None) or {}).items()))


@dataclass(frozen=True)
class _Selection:
    path: list[Fit]
    scores: list[CandidateScore]
    fixed: dict[str, Effect]
    shares: dict[str, tuple[float, float]]
    kept: Fit
    """The established effects' model."""
    assessed: dict[str, Assessment]


def _select(family: Family, train: np.ndarray, heldout: np.ndarray,
            splits: list[tuple[np.ndarray, np.ndarray]], cfg: SelectConfig,
            report: Progress | None, barred: frozenset[str] = frozenset(),
            tried_before: Tried | None = None) -> _Selection:
    """Forward selection, held parameters released, every selected effect judged."""
    path, scores, fixed = forward_select(family, train, heldout, cfg, report, barred,
                                         tried_before)
    if fixed:
        path[-1], fixed = release_held(family, path[-1], fixed, train, heldout, report)
    effect_shares = shares(family, path, heldout)
    if report and splits and path[-1].active:
        report(f"resampling {len(splits)} folds")
    # the model (and the file written from it) holds the established effects only
    kept, assessed, fixed = assess(family, path[-1], {n: s[1] for n, s in effect_shares.items()},
                                   splits, train, heldout, fixed, report, cfg.workers)
    return _Selection(path, scores, fixed, effect_shares, kept, assessed)
