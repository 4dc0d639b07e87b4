"""The diagnosis engine: locate -> hypothesise -> fit -> select -> report, as staged pure
functions over a :class:`~serpar.diagnosis.family.Family`.

Selection rule: diagnosis/forward.py (forward selection, one effect per step).

Reported values: the split chooses the model and every held-out figure is the training fit's.
Where the model then holds on the held-out rows (their residual passes the noise test, or
looks like noise), the values of the established effects and the baseline (findings, model
file) are fitted on every row, since an estimate from one half has twice the variance; where
a structured residual remains they stay the training fit's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from serpar.diagnosis.empirical import characterise
from serpar.diagnosis.empirical_refit import model_refit, outweighed
from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.findings import excess, findings_of, param_estimates, shares, verdict
from serpar.diagnosis.fit import Fit, fit_model
from serpar.diagnosis.forward import (
    Progress,
    SelectConfig,
    Tried,
    beyond_noise,
    forward_select,
)
from serpar.diagnosis.locate import chi2_p
from serpar.diagnosis.reselect import barred_reason, passed_over
from serpar.diagnosis.residual import check_residual, noise_like_but_explained
from serpar.diagnosis.result import CandidateScore, Diagnosis, Finding
from serpar.diagnosis.rivals import rivals
from serpar.diagnosis.stability import (
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
