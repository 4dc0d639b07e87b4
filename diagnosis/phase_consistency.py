"""A link's mass or inertia, established in an assembly episode only where two of its
free-motion phases (start, register, locate, inspect, align) each show it and agree on it.

Why: an episode's free motion is a few repeated moves, each phase its own poses and speeds. A
link-mass parameter fitted over all of them can take up physics the model lacks that loads one
move more than the others (rotor inertia at one phase's accelerations, friction at another's
speeds, a tilted floor at one phase's poses), and then it reads as a mass the cell does not
have. A real mass loads every move with the same number. So each phase with enough rows is
fitted on its own training rows (the main split's, the rest of the model refitted with it),
the effect must earn its parameters on that phase's held-out rows (:func:`serpar.diagnosis.fit.earns`)
in at least two phases, and the parameters it claims (beyond 2 sigma in the whole fit) must
agree between those phases within 2 sigma of their difference. Otherwise it is suspected,
with the reason.

A family opts in with ``row_phases`` (each row's phase name, "" for rows of none) and
``phase_checked`` (the effects this applies to): diagnosis/episode_family.py.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from functools import partial
from itertools import combinations

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit, earns, fit_model
from serpar.diagnosis.parallel import results, run_all

Rows = NDArray[np.int64]
AGREE_SIGMA = 2.0
"""Two phases' fits of a claimed parameter agree when within this many sigma of their
difference."""
CLAIMED_SIGMA = 2.0
"""A parameter the whole fit claims: beyond this many sigma of zero."""
MIN_PHASE_ROWS = 40
"""Training rows (and held-out rows) a phase needs to be fitted on its own (about 2 s)."""


def phase_reasons(family: Family, fit: Fit, name: str, train: Rows, heldout: Rows,
                  overrides: Mapping[str, Effect], report: Callable[[str], None] | None = None,
                  workers: int = 0) -> list[str]:
    """Why ``name`` is not established by the phases (empty: it holds; a family without
    phases, or an effect it does not check, always holds)."""
    phases = getattr(family, "row_phases", None)
    if phases is None or name not in getattr(family, "phase_checked", ()):
        return []
    values, std = np.asarray(fit.params[name]), np.asarray(fit.std[name])
    claimed = np.flatnonzero(np.abs(values) > CLAIMED_SIGMA * std)
    if claimed.size == 0:
        return []
    names = [p for p in dict.fromkeys(phases[train]) if p]
    per_phase: dict[str, tuple[bool, NDArray[np.float64], NDArray[np.float64]]] = {}
    without = tuple(a for a in fit.active if a != name)
    rows = {phase: (train[phases[train] == phase], heldout[phases[heldout] == phase])
            for phase in names}
    fitted = [p for p in names if min(rows[p][0].size, rows[p][1].size) >= MIN_PHASE_ROWS]
    if report and fitted:
        report(f"{name} in each free-motion phase alone ({', '.join(fitted)})")
    # each phase with and without the effect: independent fits, side by side
    both = results(run_all([partial(fit_model, family, active, *rows[p], fit.params, overrides)
                            for p in fitted for active in (fit.active, without)], workers))
    for k, phase in enumerate(fitted):
        full, rest = both[2 * k], both[2 * k + 1]
        per_phase[phase] = (earns(rest, full)[2], np.asarray(full.params[name])[claimed],
                            np.asarray(full.std[name])[claimed])
    holding = [p for p, (holds, _, _) in per_phase.items() if holds]
    if len(holding) < 2:
        return [(f"a link's mass loads every move: it holds in {len(holding)} of the "
                f"{len(per_phase)} free-motion phases fitted alone "
                f"({', '.join(holding) or 'none'} of {', '.join(per_phase) or 'none'}); two needed")]
    block = fit.params[name]
    labels = [_label(family, name, i, len(block)) for i in claimed]
    worst = (0.0, "", "", 0)
    for a, b in combinations(holding, 2):
        (_, va, sa), (_, vb, sb) = per_phase[a], per_phase[b]
        z = np.abs(va - vb) / np.sqrt(sa ** 2 + sb ** 2)
        k = int(np.argmax(z))
        if z[k] > worst[0]:
            worst = (float(z[k]), a, b, k)
    z, a, b, k = worst
    if z <= AGREE_SIGMA:
        return []
    return [(f"its fits in the {a} and {b} phases differ by {z:.2g} sigma ({labels[k]} = "
            f"{per_phase[a][1][k]:.3g} ± {per_phase[a][2][k]:.2g} against "
            f"{per_phase[b][1][k]:.3g} ± {per_phase[b][2][k]:.2g}): a mass would load both alike")]


def _label(family: Family, name: str, i: int, size: int) -> str:
    effect = next((e for e in family.effects if e.name == name), None)
    return effect.param_names[i] if effect is not None and len(effect.param_names) == size else f"#{i}"
