"""A selected effect that does not hold up, chosen over a rival by a hair: select again
without it.

Forward selection adds, at each step, the candidate that fits the held-out rows best. Two
candidates may fit a step almost alike (a hand payload and the last link's mass load the same
moves), and the one chosen may later fail a rule that judges the selected effects (resampling,
the two-phase rule of diagnosis/phase_consistency.py). The model then holds neither: the
rival was never tried again once the chosen one took its share. Where that happened the
selection is run once more with the failed effects barred, and the result is kept where its
established model fits the held-out rows better; the barred effects stay in the report as
suspected, with why.
"""

from __future__ import annotations

from collections.abc import Sequence

from serpar.diagnosis.result import CandidateScore

NEAR_TIE = 1.05
"""A rival fits a step "almost alike" when its held-out RMS is within this factor of the
chosen effect's."""


def passed_over(chosen: Sequence[str], scores: Sequence[CandidateScore], failed: Sequence[str]
                ) -> dict[str, str]:
    """Each of ``failed`` (effects of the selection order ``chosen`` that did not hold up) whose
    step had a rival that also earned its place and fitted within :data:`NEAR_TIE` of it,
    mapped to that rival's name."""
    out: dict[str, str] = {}
    for name in failed:
        if name not in chosen:
            continue
        step = chosen.index(name) + 1
        at_step = [s for s in scores if s.step == step and s.earns]
        mine = next((s for s in at_step if s.effect == name), None)
        if mine is None:
            continue
        rivals = [s for s in at_step if s.effect != name
                  and s.heldout_rms <= NEAR_TIE * mine.heldout_rms]
        if rivals:
            out[name] = min(rivals, key=lambda s: s.heldout_rms).effect
    return out


def barred_reason(name: str, rival: str) -> str:
    return (f"chosen over {rival} by a hair, it does not hold up: the selection was run again "
            f"without it")
