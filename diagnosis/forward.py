"""Stage "select": forward selection, one effect per step, on one split of the rows.

At each step every candidate not yet in the model is fitted together with the current model
on the training rows (scipy ``least_squares``) and scored on the held-out rows. A candidate
with k parameters *earns its parameters* when it lowers the information criterion on both
splits:

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

The candidates of a step are independent fits from the same model: they run side by side
(diagnosis/parallel.py), the longest first, and a second selection on the same split takes
the fits the first made from the same model (:data:`Tried`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial

import numpy as np
import scipy.stats

from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit, earns, fit_model
from serpar.diagnosis.locate import chi2_p
from serpar.diagnosis.parallel import run_all
from serpar.diagnosis.result import CandidateScore
from serpar.diagnosis.stability import N_FOLDS, fit_identified
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
