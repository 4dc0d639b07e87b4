"""Stage "hold up": does a selected effect survive resampling, and is it a finding at all?

An effect the forward selection kept is *established* only when

- its parameters are physically admissible: fitted under the physical bounds of its
  :class:`~serpar.diagnosis.family.Effect` (friction, compliance, clearance >= 0), so this holds
  by construction;
- none sits on a search bound: a parameter there with a sigma as wide as its range is one the
  data do not identify and is held at zero (:func:`fit_identified`); one the data do identify
  says the candidate cannot be what the data show;
- it is needed again under resampling: on each of ``k`` folds (other training / held-out
  rows) the model without it is refitted and the effect must still earn its parameters over
  that model, on at least ``MIN_FREQUENCY`` of the folds, predicting the same correction
  (contribution to the residual) as on the main fit;
- it removes a material share of what the effects ranked before it left;
- where the residual has parallel channels (a family's ``channels``, e.g. the torque of each
  joint), what it changes in each channel is what that channel's held-out residual shows, and
  a channel it cannot change does not show the same (diagnosis/channel_check.py).

Uncertainties: the larger of the local (Jacobian) one and the folds' jackknife (Resampled).
Everything else the selection kept is "suspected, not established", with the reasons.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.channel_check import ChannelCheck, channel_check
from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit, blocks_of, earns, fit_model
from serpar.diagnosis.parallel import run_all
from serpar.diagnosis.phase_consistency import phase_reasons

Rows = NDArray[np.int64]

N_FOLDS = 5
MIN_FREQUENCY = 0.8
"""Share of the folds on which an effect must earn its parameters again."""
MIN_SHARE_OF_REMAINING = 0.05
"""An effect must remove at least this share of the excess held-out residual that the
effects ranked before it left."""
MIN_AGREEMENT = 0.8
"""Cosine between an effect's contribution on a fold and on the main fit, on every fold where
it is needed."""
SIGNIFICANT = 3.0
"""An amplitude within this many sigma of zero does not identify the shapes it scales."""
UNIDENTIFIED = 0.25
"""A parameter on a search bound whose sigma exceeds this share of its search range is one
the data do not identify: it is held at zero and the model refitted, instead of letting it
trade against the others at the bound."""


@dataclass(frozen=True)
class Resampled:
    """One effect of the final model over the folds."""

    effect: str
    folds: int
    """Folds that hold out rows the effect acts on (one that acts on a few rows, the chamfer
    slides of an episode, cannot be tested on a fold that holds out none of them)."""
    kept: int
    """Folds on which the effect earned its parameters over the model without it."""
    values: NDArray[np.float64]
    """(folds, n_params) the effect's parameters fitted on each fold."""
    consistent: bool
    """The effect predicted the same thing (contribution cosine >= MIN_AGREEMENT) on every fold
    where it was needed."""

    @property
    def frequency(self) -> float:
        return self.kept / self.folds if self.folds else 0.0

    @property
    def jackknife_std(self) -> NDArray[np.float64]:
        """Each parameter's delete-a-group jackknife error over the k folds, sqrt((k-1)/k *
        sum (x_i - mean)^2), model error included: (k-1)/sqrt(k) times the folds' plain spread,
        as each two folds share all but two k-ths of their rows."""
        k = len(self.values)
        if k < 2:
            return np.zeros(self.values.shape[1])
        dev = self.values - self.values.mean(axis=0)
        return np.sqrt((k - 1) / k * np.sum(dev**2, axis=0))


def folds(family: Family, k: int = N_FOLDS) -> list[tuple[Rows, Rows]]:
    """The family's own folds (``family.folds(k)``), else contiguous blocks of rows dealt
    round-robin to ``k`` folds (4 blocks per fold: each fold holds out rows from the whole
    recording, in stretches long enough for time-correlated rows to stay together)."""
    own = getattr(family, "folds", None)
    if callable(own):
        return [(np.asarray(a, np.int64), np.asarray(b, np.int64)) for a, b in own(k)]
    return default_folds(int(family.n_samples), k)


def default_folds(n: int, k: int) -> list[tuple[Rows, Rows]]:
    """Contiguous blocks of the n rows dealt round-robin to k folds."""
    rows = np.arange(n)
    blocks = np.minimum((rows * 4 * k) // max(n, 1), 4 * k - 1)
    out = []
    for f in range(k):
        held = rows[blocks % k == f]
        if held.size and held.size < n:
            out.append((rows[blocks % k != f], held))
    return out


def fit_identified(family: Family, active: tuple[str, ...], train: Rows, heldout: Rows,
                   start: Mapping[str, NDArray[np.float64]] | None,
                   overrides: Mapping[str, Effect]) -> tuple[Fit, dict[str, Effect]]:
    """:func:`fit_model`, then every parameter on a search bound that the data do not identify
    (sigma > UNIDENTIFIED of its range) held at zero and the model refitted, until none is; a
    shape parameter (:attr:`Effect.amplitude_of`) on a search bound whose amplitude is within
    SIGNIFICANT sigma of zero is held with its amplitude (the term is absent there: its shape
    is not seen)."""
    fixed = dict(overrides)
    fit = fit_model(family, active, train, heldout, start, fixed)
    for _ in range(3):
        loose = {}
        for name in active:
            e = block_of(family, active, name, fixed)
            std = fit.std[name]
            values = fit.params[name]
            idx = [i for i in e.pinned(values)
                   if std[i] > UNIDENTIFIED * (e.upper[i] - e.lower[i])]
            for i in e.pinned(values):  # a shape pinned where its amplitude is nil
                a = e.amplitude_of[i] if e.amplitude_of else -1
                if a >= 0 and not abs(values[a]) > SIGNIFICANT * std[a]:
                    idx += [a, *e.shapes_of(a)]
            idx = sorted(set(idx))
            if idx:
                loose[name] = e.fix(idx)
        if not loose:
            break
        fixed.update(loose)
        fit = fit_model(family, active, train, heldout, fit.params, fixed)
    return fit, fixed


def release_held(family: Family, fit: Fit, fixed: Mapping[str, Effect], train: Rows,
                 heldout: Rows, report: Callable[[str], None] | None = None
                 ) -> tuple[Fit, dict[str, Effect]]:
    """The selected model with each effect's held parameters freed again, one effect at a
    time, started from the effect's own start values, and kept where the refit earns them
    (:func:`earns`). A parameter held when its effect was added may be identified once later
    effects explain what it stood beside: a joint's sigmoid friction pinned while the payload
    was missing from the model stays at zero otherwise, and a viscous term stands in for it."""
    fixed = dict(fixed)
    for name in [n for n in fit.active if n in fixed]:
        rest = {n: e for n, e in fixed.items() if n != name}
        effect = block_of(family, fit.active, name, rest)
        start = {k: np.array(v, float) for k, v in fit.params.items()}
        held = list(fixed[name].fixed)
        start[name][held] = np.clip(effect.x0[held], effect.lower[held], effect.upper[held])
        if report:
            report(f"{name}: its {len(held)} held parameter(s) freed again")
        new, new_fixed = fit_identified(family, fit.active, train, heldout, start, rest)
        if earns(fit, new)[2]:
            fit, fixed = new, new_fixed
    return fit, fixed


def resample(family: Family, final: Fit, splits: list[tuple[Rows, Rows]],
             overrides: Mapping[str, Effect] | None = None,
             report: Callable[[str], None] | None = None, workers: int = 0
             ) -> dict[str, Resampled]:
    """Each effect of ``final`` on each split: fitted with the others, whether it still earns
    its parameters over the model refitted without it, and whether it predicts the same thing
    (its contribution to the residual over all rows, cosine >= MIN_AGREEMENT with the main
    fit's: a many-parameter effect may trade parameters between folds, but not its physics)."""
    start = dict(final.params)
    names = final.active
    every = np.arange(int(family.n_samples))
    main = {n: _contribution(family, final.params, n, every) for n in names}
    kept = {n: 0 for n in names}
    tried = {n: 0 for n in names}
    values: dict[str, list[NDArray[np.float64]]] = {n: [] for n in names}
    agree: dict[str, list[float]] = {n: [] for n in names}
    say = report or (lambda _msg: None)
    # every fold's model first, then every model without one effect: each a fit of its own
    fulls = _fits(family, [(names, tr, held) for tr, held in splits], start, overrides, workers,
                  lambda k: say(f"fold {k + 1} of {len(splits)}: {', '.join(names)}"))
    without = [(k, n) for k, (_, held) in enumerate(splits) for n in names
               # a fold that holds out none of the rows it acts on cannot test it
               if np.any(_contribution(family, fulls[k].params, n, held))]
    refits = _fits(family, [(tuple(a for a in names if a != n), *splits[k]) for k, n in without],
                   start, overrides, workers,
                   lambda j: say(f"fold {without[j][0] + 1} of {len(splits)}: "
                                 f"without {without[j][1]}"))
    for (k, n), less in zip(without, refits):
        tried[n] += 1
        if earns(less, fulls[k])[2]:
            kept[n] += 1
            agree[n].append(_cosine(_contribution(family, fulls[k].params, n, every), main[n]))
    for full in fulls:
        for n in names:
            values[n].append(np.asarray(full.params[n], float))
    return {n: Resampled(n, tried[n], kept[n], np.array(values[n]),
                         all(a >= MIN_AGREEMENT for a in agree[n]))
            for n in names}


def _fits(family: Family, models: list[tuple[tuple[str, ...], Rows, Rows]],
          start: Mapping[str, NDArray[np.float64]], overrides: Mapping[str, Effect] | None,
          workers: int, started: Callable[[int], None]) -> list[Fit]:
    """:func:`fit_model` of each (effects, training rows, held-out rows), side by side
    (diagnosis/parallel.py), in order; a fit that raises raises here."""
    jobs = [partial(fit_model, family, active, tr, held, start, overrides)
            for active, tr, held in models]
    out = []
    for ok, got in run_all(jobs, workers, lambda what, k: started(k) if what == "start" else None):
        if not ok:
            raise got
        out.append(got)
    return out


def _contribution(family: Family, params: Mapping[str, NDArray[np.float64]], name: str,
                  rows: Rows) -> NDArray[np.float64]:
    """What effect ``name`` changes in the whitened residual of ``rows``."""
    without = {k: v for k, v in params.items() if k != name}
    return family.residual(params, rows) - family.residual(without, rows)


def _cosine(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    return float(a @ b / (na * nb)) if na > 0 and nb > 0 else 0.0


def reasons_not_established(effect: Effect, values: NDArray[np.float64],
                            std: NDArray[np.float64], resampled: Resampled | None,
                            share_of_remaining: float, channels: ChannelCheck | None = None
                            ) -> list[str]:
    """Why a selected effect is only suspected (empty: it is established)."""
    why = []
    pinned = effect.pinned(values)
    if pinned:
        shown = ", ".join(f"{effect.param_names[i]} = {values[i]:.3g} {effect.units[i]}"
                          .rstrip() + f" (± {std[i]:.2g})" for i in pinned[:3])
        more = f" and {len(pinned) - 3} more" if len(pinned) > 3 else ""
        why.append(f"pinned on its search bound: {shown}{more}")
    if resampled is not None:
        if resampled.folds == 0:
            why.append("no resampled fold holds out rows it acts on")
        elif resampled.frequency < MIN_FREQUENCY:
            why.append(f"needed on {resampled.kept} of {resampled.folds} resampled folds "
                       f"(< {MIN_FREQUENCY:.0%})")
        elif not resampled.consistent:
            why.append("it predicts different corrections on different resampled folds")
    if channels is not None:
        why += channels.reasons()
    if share_of_remaining < MIN_SHARE_OF_REMAINING:
        why.append(f"explains only {100 * share_of_remaining:.2g} % of what the effects "
                   "before it left")
    return why


@dataclass(frozen=True)
class Assessment:
    """One selected effect, judged in the last model that held it."""

    reasons: tuple[str, ...]
    """Empty: established."""
    resampled: Resampled | None
    fit: Fit
    """The model it was judged in (its parameters and local sigma)."""


def assess(family: Family, final: Fit, share_of_remaining: Mapping[str, float],
           splits: list[tuple[Rows, Rows]], train: Rows, heldout: Rows,
           overrides: Mapping[str, Effect], report: Callable[[str], None] | None = None,
           workers: int = 0) -> tuple[Fit, dict[str, Assessment], dict[str, Effect]]:
    """Judge every effect of ``final``; drop the least needed one that does not hold up, refit
    the rest on the main split and judge them again in that model (an effect must neither ride
    on nor be spoiled by one that trades against it), until every effect left holds up. Returns the model of
    the established effects, the assessment of every selected one, and the effects with the
    parameters the data do not identify held at zero."""
    out: dict[str, Assessment] = {}
    fit, overrides = final, dict(overrides)
    while fit.active:
        res = resample(family, fit, splits, overrides, report, workers) if splits else {}
        failing = []
        for name in fit.active:
            effect = block_of(family, fit.active, name, overrides)
            r = res.get(name)
            why = reasons_not_established(effect, fit.params[name], combined_std(fit, name, r), r,
                                          share_of_remaining[name],
                                          channel_check(family, fit.params, name, heldout))
            if not why:  # only then: it refits the model per phase
                why = phase_reasons(family, fit, name, train, heldout, overrides, report, workers)
            out[name] = Assessment(tuple(why), r, fit)
            if why:
                failing.append((r.frequency if r is not None else 1.0, -fit.active.index(name),
                                name))
        if not failing:
            break
        # one at a time, the least needed (then the latest added) first: the others are judged
        # again without it
        drop = min(failing)[2]
        fit, overrides = fit_identified(family, tuple(a for a in fit.active if a != drop),
                                        train, heldout, fit.params, overrides)
    return fit, out, overrides


def combined_std(fit: Fit, name: str, resampled: Resampled | None) -> NDArray[np.float64]:
    """The larger of the local (Jacobian) sigma and the jackknife over the resampled folds."""
    local = np.asarray(fit.std[name], float)
    return local if resampled is None else np.maximum(local, resampled.jackknife_std)


def block_of(family: Family, active: tuple[str, ...], name: str,
             overrides: Mapping[str, Effect] | None = None) -> Effect:
    return next(b for b in blocks_of(family, active, overrides) if b.name == name)
