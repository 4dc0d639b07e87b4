"""The journal/bore friction in ``serpar sim2real``: the updated simulator's rerun, and the
bore's mu read against it from the insertions (diagnosis/bore_friction.py), with a second rerun
at another mu where the cell's in-bore push differs from the rerun's."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np

from serpar.checks.background_rerun import BackgroundRerun
from serpar.checks.sim2real import (
    MU_RANGE,
    NOMINAL_MU,
    OutcomeDiff,
    RealEpisode,
    Tick,
    outcomes_of,
    paired,
    rerun,
    updated_contact_friction,
    write_model_file,
)
from serpar.diagnosis.bore_friction import BoreFriction, bore_friction
from serpar.diagnosis.task_outcomes import HoleOutcome

MU_STEP_UP, MU_STEP_DOWN = 0.25, 0.1
"""The second mu a bore-friction rerun takes, above or below the updated rerun's (the concealed
cells' range: 0.1-0.5)."""


def push_difference(real: list[HoleOutcome], sim: list[HoleOutcome]) -> OutcomeDiff:
    """The cell's in-bore push minus the simulator's, paired per hole, with its 95 % CI."""
    by_hole = {(h.cycle, h.hole): h.bore_axial for h in sim if h.bore_axial is not None}
    return paired([h.bore_axial[0] - by_hole[(h.cycle, h.hole)][0] for h in real
                   if h.bore_axial is not None and (h.cycle, h.hole) in by_hole])


def _second_mu(push: float, mu0: float) -> float:
    """The mu to rerun at where the cell pushes harder (``push`` > 0) or less than ``mu0``."""
    return mu0 + (MU_STEP_UP if push > 0 else -min(MU_STEP_DOWN, mu0 - MU_RANGE[0]))


def bore_rerun_mu(real: list[HoleOutcome], sim: list[HoleOutcome], mu0: float
                  ) -> tuple[float | None, str]:
    """The second mu to rerun the holes at for the bore's friction, or None with why not: the
    real in-bore push against the simulator's at ``mu0``, paired per hole; where it agrees
    within its 95 % CI there is nothing to fit and no rerun is spent."""
    d = push_difference(real, sim)
    if d.diff is None or d.ci is None:
        return None, (f"{d.n} seated insertion(s) with an in-bore travel in both the cell and "
                      "the simulator; 2 needed")
    if abs(d.diff) <= d.ci:
        return None, (f"the in-bore push agrees with the simulator's at mu {mu0:.3g} "
                      f"({d.diff:+.3g} ± {d.ci:.2g} N over {d.n} holes): nothing to fit")
    return _second_mu(d.diff, mu0), ""


def bore_guess(real: list[HoleOutcome], nominal: list[HoleOutcome], mu0: float) -> float | None:
    """The second mu :func:`bore_rerun_mu` would take if the diagnosed simulator's in-bore push
    differs from the cell's in the direction the nominal's does (None without 2 holes to tell
    by): what a rerun started ahead of need, beside the updated one, runs at."""
    d = push_difference(real, nominal)
    if d.diff is None or d.ci is None or d.diff == 0.0:
        return None
    return _second_mu(d.diff, mu0)


def updated_rerun(episodes: list[RealEpisode], real: list[HoleOutcome], model: dict[str, object],
                  out: Path, step: Tick, nominal: list[HoleOutcome] | None = None,
                  beside: Tick | None = None
                  ) -> tuple[dict[str, object], BoreFriction, list[Path], str]:
    """The diagnosed simulator on the same holes (``OUT/updated``), and the bore's friction read
    against it (diagnosis/bore_friction.py): the updated model (with the bore's mu where the
    insertions give one), the bore's finding, the updated rerun's folders and a note.

    The in-bore push also carries the arm's own physics (a hand's weight in the axial estimate,
    the drive friction the force loop works against), which a line through reruns on the
    nominal arm would read as mu: the push is read against the diagnosed arm, whose rerun at
    the model's mu is the line's first point. Where the cell's push differs from it, every hole
    again at a second mu (``OUT/bore_mu``); where that gives a mu, the first rerun becomes
    ``OUT/bore_mu0`` and the holes run once more with it. The second mu's rerun starts beside
    the updated one (a rerun holds one core), at the mu the ``nominal`` rerun's push points to
    (:func:`bore_guess`), its lines to ``beside`` (default ``step``); where the updated rerun
    asks for another mu or none, it is cancelled."""
    arm_path = write_model_file(model, out)
    mu0 = updated_contact_friction(model)
    mu = NOMINAL_MU if mu0 is None else mu0
    guess = bore_guess(real, nominal, mu) if nominal else None
    ahead = None
    if guess is not None:
        step(f"beside it, the holes at mu {guess:.3g} too, in case the bore's friction asks "
             "for them (the nominal rerun's in-bore push points there)")
        ahead = BackgroundRerun(episodes, out / "bore_mu", str(arm_path), guess, beside or step)
    try:
        updated = rerun(episodes, out / "updated", str(arm_path), mu0, step)
        at_mu0 = outcomes_of(updated)
        mu1, why = bore_rerun_mu(real, at_mu0, mu)
        if ahead is not None and mu1 != guess:
            ahead.cancel()
            ahead = None
        if mu1 is None:
            return model, BoreFriction(None, None, 0, (mu, mu), why,
                                       agrees=why.startswith("the in-bore push agrees")), updated, ""
        step(f"the in-bore push differs from the diagnosed simulator's: the holes again at mu "
             f"{mu1:.3g} (the bore's friction)" + (", under way beside the updated rerun"
                                                    if ahead is not None else ""))
        at_mu1 = outcomes_of(ahead.result() if ahead is not None
                             else rerun(episodes, out / "bore_mu", str(arm_path), mu1, step))
        ahead = None
    except KeyboardInterrupt:
        if ahead is not None:
            ahead.stop()
        raise
    bore = bore_friction(real, at_mu0, at_mu1, mu, mu1)
    model, note = with_bore_friction(model, bore)
    contact = updated_contact_friction(model)
    if contact == mu0:
        return model, bore, updated, note
    shutil.rmtree(out / "bore_mu0", ignore_errors=True)  # a replaced output's (--force)
    (out / "updated").rename(out / "bore_mu0")
    path = write_model_file(model, out)
    step(f"the bore's mu {contact:.3g} in the update: the holes once more")
    return model, bore, rerun(episodes, out / "updated", str(path), contact, step), note


def with_bore_friction(model: dict[str, object], found: BoreFriction) -> tuple[dict[str, object], str]:
    """The updated model with the bore's friction the insertions show (as ``contact_friction``'s
    d_mu), and a note; the diagnosis's own estimate (chamfer slides) is kept where it has one
    and the two disagree, their inverse-variance mean taken where they agree within 2 sigma."""
    if found.mu is None or found.std is None:
        return model, ""
    effects = list(model["effects"])  # type: ignore[call-overload]
    params = dict(model["params"])  # type: ignore[call-overload]
    d_mu, std = found.mu - NOMINAL_MU, found.std
    note = f"{found.words()}: in the updated model"
    if "contact_friction" in effects:
        block = params["contact_friction"]
        slide, slide_std = float(block["values"][0]), float(block["std"][0])
        gap = abs(slide - d_mu) / math.hypot(slide_std, std)
        if gap > 2.0:
            return model, (f"{found.words()}: {gap:.2g} sigma from the chamfer slides' mu = "
                           f"{NOMINAL_MU + slide:.3g} ± {slide_std:.2g}; the updated model keeps "
                           "the slides'")
        w = np.array([slide_std, std]) ** -2.0
        d_mu = float((w @ [slide, d_mu]) / w.sum())
        std = float(w.sum() ** -0.5)
        note = (f"{found.words()}, with the chamfer slides' (within {gap:.2g} sigma): mu = "
                f"{NOMINAL_MU + d_mu:.3g} ± {std:.2g} in the updated model")
    else:
        effects.append("contact_friction")
    params["contact_friction"] = {"values": [d_mu], "std": [std], "names": ["d_mu"]}
    return {**model, "effects": effects, "params": params}, note
