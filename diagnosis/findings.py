"""The report stage of a diagnosis: each selected effect's share of the residual, its finding
(parameters, evidence, whether it held up) and the one-line verdict (diagnosis/select.py runs
the stages)."""

from __future__ import annotations

import itertools
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.empirical import EmpiricalTerm
from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit, earns
from serpar.diagnosis.result import NO_MISSING_PHYSICS, Finding, ParamEstimate
from serpar.diagnosis.stability import Assessment, Rows, block_of, combined_std


def excess(fit: Fit) -> float:
    """Held-out mean square above the noise floor (whitened noise has mean square 1)."""
    return max(fit.heldout_chi2 / max(fit.n_heldout, 1) - 1.0, 0.0)


def shares(family: Family, path: list[Fit], heldout: Rows) -> dict[str, tuple[float, float]]:
    """Per selected effect: the share of the baseline's excess held-out residual it removed
    when it was added, and the share of what the effects before it left on the held-out rows it
    acts on (an effect on a few rows, the chamfer slides of an episode, is judged on those, not
    on the arm's thousands)."""
    excess0, out = excess(path[0]), {}
    for prev, fit in itertools.pairwise(path):
        name = fit.active[-1]
        removed = excess(prev) - excess(fit)
        without = {k: v for k, v in fit.params.items() if k != name}
        after = family.residual(fit.params, heldout)
        reach = (after - family.residual(without, heldout)) != 0
        out[name] = (float(np.clip(removed / excess0 if excess0 > 0 else 0.0, 0, 1)),
                     _share_where_it_acts(family, heldout, family.residual(prev.params, heldout),
                                          after, reach))
    return out


def _share_where_it_acts(family: Family, heldout: Rows, before: NDArray[np.float64],
                         after: NDArray[np.float64], reach: NDArray[np.bool_]) -> float:
    """The share of the excess over noise it removes, judged per independent part of the data
    (the family's ``residual_parts``: an episode's arm rows and its chamfer slides; else the
    entries it acts on), the largest: a whole held-out excess would be clipped at the noise
    floor, where arm rows a little under it hide what the slides above it lose."""
    parts = getattr(family, "residual_parts", None)
    if callable(parts):
        b, a = parts(heldout, before), parts(heldout, after)
        pairs = [(b[k], a[k]) for k in b]
    else:
        pairs = [(before[reach], after[reach])]
    best = 0.0
    for b_part, a_part in pairs:
        left = float(b_part @ b_part) - b_part.size
        if left > 0:
            best = max(best, (float(b_part @ b_part) - float(a_part @ a_part)) / left)
    return float(np.clip(best, 0.0, 1.0))


def param_estimates(effect: Effect, values: NDArray[np.float64], std: NDArray[np.float64]
                    ) -> tuple[ParamEstimate, ...]:
    """A block's parameters with their sigma; those held at zero are not estimates: left out."""
    return tuple(ParamEstimate(p, float(v), float(s), u) for i, (p, v, s, u) in
                 enumerate(zip(effect.param_names, values, std, effect.units))
                 if i not in effect.fixed)


def findings_of(family: Family, path: list[Fit], shares: dict[str, tuple[float, float]],
                assessed: dict[str, Assessment], fixed: dict[str, Effect], estimate: Fit,
                demoted: Mapping[str, tuple[str, ...]]) -> list[Finding]:
    """One finding per selected effect. An established one takes its values from ``estimate``
    (the established effects fitted on every row); a suspected one from the model it was last
    judged in. ``demoted``: established effects set back to suspected afterwards, with why."""
    out = []
    for rank, (prev, fit) in enumerate(itertools.pairwise(path), start=1):
        name = fit.active[-1]
        d_bic, d_held, _ = earns(prev, fit)
        a = assessed[name]
        reasons = a.reasons + tuple(demoted.get(name, ()))
        source = estimate if not reasons and name in estimate.params else a.fit
        effect = block_of(family, source.active, name, fixed)
        values = source.params[name]
        std = combined_std(source, name, a.resampled)
        estimates = param_estimates(effect, values, std)
        notes = []
        if effect.excess_words and values[0] < 0:
            notes.append(effect.excess_words.format(
                value=f"{-values[0]:.3g} {effect.units[0]}".rstrip()))
        if effect.fixed:
            notes.append("not identified by these data, held at 0: "
                         + ", ".join(effect.param_names[i] for i in effect.fixed))
        out.append(Finding(rank, name, effect.summary, estimates, shares[name][0], d_bic, d_held,
                           shares[name][1], established=not reasons, reasons=reasons,
                           stability=None if a.resampled is None else a.resampled.frequency,
                           note="; ".join(notes)))
    return out


def verdict(findings: list[Finding], baseline_quiet: bool, residual_words: str,
            empirical: EmpiricalTerm | None = None) -> str:
    """``baseline_quiet``: the baseline alone is at the noise floor in every part of the data."""
    if not findings and baseline_quiet:
        return NO_MISSING_PHYSICS
    established = [f.summary for f in findings if f.established]
    suspected = [f"{f.summary} ({'; '.join(f.reasons)})" for f in findings if not f.established]
    if not findings:
        head = "no candidate effect earns its parameters on held-out data"
    elif established:
        head = "missing physics: " + ", ".join(established)
    else:
        head = "no finding holds up"
    if suspected:
        head += "; suspected, not established: " + ", ".join(suspected)
    tail = ""
    if empirical is not None and empirical.terms:
        tail = (". What is left, characterised as an empirical term (a hypothesis, not a "
                f"finding): {empirical.words()}")
    elif empirical is not None:
        tail = f". Outside the library: {empirical.words()}"
    return f"{head}. {residual_words[0].upper()}{residual_words[1:]}{tail}"
