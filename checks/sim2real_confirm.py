"""An established effect stays in ``serpar sim2real``'s updated model only if the updated rerun
confirms it: the outcomes it moves move toward the real cell.

One rerun of every hole with the whole update shows what the update did, not what each effect
did. Where that rerun leaves some outcome further from the cell than the nominal simulator did
(and beyond its interval), each established effect is taken out in turn and
:data:`CONFIRM_HOLES` holes rerun without it: on those holes the effect's own move of each
outcome that moved away is the rerun with the whole update minus the one without it. The holes
are the first the cell and the updated rerun both seated where an outcome of a seated insertion
moved away (a hole one of them did not seat has none to compare), rerun once more with the
whole update where they are not the recording's first (a rerun of some holes starts where the
recording's first hole does); else the recording's first holes. An effect is confirmed when
those outcomes end, in sum, nearer the cell with it than without it, each outcome's distance
in units of its interval before the update; an effect that does not is dropped, and the holes
are rerun once more without the dropped ones (the update's last rerun). Where that last rerun
leaves more outcomes beyond their interval than the update did, the drop is undone: a few holes
judged one effect, all of them judge the update, and the update stays, with the reason.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from serpar.checks.background_rerun import Job, reruns_side_by_side
from serpar.checks.sim2real import (
    OutcomeDiff,
    RealEpisode,
    Tick,
    beyond_ci,
    compare,
    outcomes_of,
    rerun,
    updated_contact_friction,
)
from serpar.diagnosis.result import Finding
from serpar.diagnosis.task_outcomes import OUTCOMES, RESOLUTION, HoleOutcome
from serpar.sim.model_file import DiagnosisModel

CONFIRM_HOLES = 2
"""Holes rerun without each effect (see the module docstring for which)."""
PER_SEATED = ("seated_depth", "peak_axial_force", "peak_lateral_force", "contact_to_seated",
              "misalignment_at_contact", "chamfer_slide")
"""Outcomes a hole has only where its journal seated."""
MOVED = 1e-9
"""An outcome an effect moves by less than this (beyond its resolution) is not moved by it."""


@dataclass(frozen=True)
class Confirmation:
    effect: str
    confirmed: bool
    moves: dict[str, tuple[float, float]]
    """Outcome -> (mean |real - sim| with the effect, without it) over the rerun holes."""
    holes: tuple[int, ...] = ()
    """The holes rerun without it."""
    kept_because: str = ""
    """Not confirmed, yet kept: why (the holes rerun without the unconfirmed went further)."""

    @property
    def dropped(self) -> bool:
        return not self.confirmed and not self.kept_because

    def words(self) -> str:
        shown = ", ".join(f"{n} {w:.3g} with / {wo:.3g} without" for n, (w, wo) in self.moves.items())
        verdict = ("confirmed" if self.confirmed
                   else f"not confirmed, kept: {self.kept_because}" if self.kept_because
                   else "dropped: it moves the outcomes away from the cell")
        on = f" on holes {', '.join(map(str, self.holes))}" if self.holes else ""
        return f"{self.effect} {verdict} ({shown or 'it moves no outcome on these holes'}{on})"

    def as_dict(self) -> dict[str, object]:
        return {"effect": self.effect, "confirmed": self.confirmed, "holes": list(self.holes),
                "kept_because": self.kept_because or None,
                "moves": {n: {"with": w, "without": wo} for n, (w, wo) in self.moves.items()}}


def to_confirm(established: Sequence[str], bore_mu: float | None, findings: Sequence[Finding],
               carried: Sequence[str]) -> list[str]:
    """What the rerun must bear out: the established effects, a bore friction the insertions
    gave (not already established), and every finding the updated model ``carried`` without
    establishing it (the one of an "A or B" pair a model must hold)."""
    out = list(established)
    if bore_mu is not None and "contact_friction" not in out:
        out.append("contact_friction")
    return out + [f.effect for f in findings
                  if not f.established and f.effect in carried and f.effect not in out]


def without_effect(model: dict[str, object], name: str, prior: DiagnosisModel) -> dict[str, object]:
    """The updated model with ``name`` taken out: back to the prior's value where the prior
    has the effect (the finding was a correction), else gone."""
    params = dict(model["params"])  # type: ignore[call-overload]
    effects = list(model["effects"])  # type: ignore[call-overload]
    if name in prior.effects:
        block = prior.block(name)
        params[name] = {"values": list(block.values), "std": list(block.std),
                        "names": list(block.names)}
    else:
        effects.remove(name)
        params.pop(name, None)
    return {**model, "effects": effects, "params": params}


def _by_hole(outcomes: list[HoleOutcome]) -> dict[tuple[int, int | None], dict[str, float]]:
    return {(h.cycle, h.hole): h.values for h in outcomes}


def judge(name: str, real: list[HoleOutcome], with_it: list[HoleOutcome],
          without: list[HoleOutcome], before: dict[str, OutcomeDiff],
          judged: Sequence[str] = tuple(OUTCOMES)) -> Confirmation:
    """Whether effect ``name`` moves the ``judged`` outcomes (those the update moved away from
    the cell) of the rerun holes toward the cell."""
    r, w, wo = _by_hole(real), _by_hole(with_it), _by_hole(without)
    keys = [k for k in wo if k in r and k in w]
    moves: dict[str, tuple[float, float]] = {}
    net = 0.0
    for o in (o for o in OUTCOMES if o in judged):
        trio = np.array([(r[k][o], w[k][o], wo[k][o]) for k in keys], float)
        trio = trio[np.all(np.isfinite(trio), axis=1)]
        if not trio.size or np.abs(trio[:, 1] - trio[:, 2]).max() <= RESOLUTION.get(o, 0.0) + MOVED:
            continue
        near, far = np.abs(trio[:, 0] - trio[:, 1]).mean(), np.abs(trio[:, 0] - trio[:, 2]).mean()
        moves[o] = (float(near), float(far))
        scale = max(before[o].ci or 0.0, RESOLUTION.get(o, 0.0), abs(before[o].diff or 0.0), 1e-12)
        net += (near - far) / scale
    return Confirmation(name, net <= 0.0, moves)


def confirm_holes(real: list[HoleOutcome], updated: list[HoleOutcome], judged: Sequence[str]
                  ) -> list[int]:
    """Positions (in the recording's order) of the holes to rerun without each effect: the
    first :data:`CONFIRM_HOLES` the cell and the updated rerun both seated where a judged
    outcome is a seated insertion's, else (or too few such) the first holes."""
    first = list(range(min(CONFIRM_HOLES, len(real))))
    if not any(o in PER_SEATED for o in judged):
        return first
    both = [k for k, (r, u) in enumerate(zip(real, updated))
            if r.values.get("seated") == 1.0 and u.values.get("seated") == 1.0]
    return both[:CONFIRM_HOLES] if len(both) >= CONFIRM_HOLES else first


def confirm(longest: RealEpisode, effects: list[str], model: dict[str, object],
            prior: DiagnosisModel, updated_folder: Path, before: dict[str, OutcomeDiff],
            judged: Sequence[str], out: Path, tick: Tick, beside: Tick | None = None,
            workers: int = 0) -> list[Confirmation]:
    """Each of ``effects`` judged on :func:`confirm_holes` of ``longest`` rerun without it (the
    reruns on ``workers`` processes, 0: one per core; their lines to ``beside``, default
    ``tick``)."""
    real_all = outcomes_of([longest.folder])
    updated = outcomes_of([updated_folder])
    picked = confirm_holes(real_all, updated, judged)
    holes = tuple(tuple(longest.config.holes)[k] for k in picked)  # type: ignore[arg-type]
    sample = dataclasses.replace(longest, config=dataclasses.replace(longest.config, holes=holes))
    real = _renumbered([real_all[k] for k in picked])
    out.mkdir(parents=True, exist_ok=True)
    jobs: list[Job] = []
    first = picked == list(range(len(picked)))  # the recording's first holes: as the update ran them
    if not first:
        path = out / "with_all.model.json"
        path.write_text(json.dumps(model, indent=2))
        tick(f"confirming: holes {', '.join(map(str, holes))} with the whole update")
        jobs.append(([sample], out / "with_all", str(path), updated_contact_friction(model)))
    for name in effects:
        reduced = without_effect(model, name, prior)
        path = out / f"without_{name}.model.json"
        path.write_text(json.dumps(reduced, indent=2))
        tick(f"confirming {name}: {len(holes)} hole(s) without it")
        jobs.append(([sample], out / f"without_{name}", str(path),
                      updated_contact_friction(reduced)))
    # independent reruns of a few holes each: side by side, one per core
    runs = [outcomes_of(f) for f in reruns_side_by_side(jobs, beside or tick, workers)]
    with_it = updated[:len(picked)] if first else runs.pop(0)
    found = [dataclasses.replace(judge(name, real, with_it, without, before, judged), holes=holes)
             for name, without in zip(effects, runs)]
    return found


def _renumbered(holes: list[HoleOutcome]) -> list[HoleOutcome]:
    """The cell's outcomes of some holes keyed as a rerun of just those holes keys them."""
    return [dataclasses.replace(h, cycle=k) for k, h in enumerate(holes)]


def away_from_cell(before: dict[str, OutcomeDiff], after: dict[str, OutcomeDiff]) -> list[str]:
    """Outcomes the update moved further from the cell (beyond their resolution) and left
    beyond their interval."""
    return [n for n in OUTCOMES if before[n].diff is not None and after[n].diff is not None
            and abs(after[n].diff) > abs(before[n].diff) + RESOLUTION.get(n, 0.0)  # type: ignore[arg-type]
            and beyond_ci(n, after[n])]


def confirmed_update(episodes: list[RealEpisode], real: list[HoleOutcome],
                     before: dict[str, OutcomeDiff], after: dict[str, OutcomeDiff],
                     updated_folders: list[Path], model: dict[str, object], prior: DiagnosisModel,
                     effects: list[str], out: Path, tick: Tick, beside: Tick | None = None,
                     workers: int = 0
                     ) -> tuple[dict[str, object], dict[str, OutcomeDiff], list[Confirmation]]:
    """Where the updated rerun left an outcome further from the cell, each of ``effects``
    judged by :func:`confirm` (``beside``, ``workers``: its reruns'); the unconfirmed dropped
    and every hole rerun once more without them. Returns the model, the outcomes' differences
    after, and the judgements."""
    away = away_from_cell(before, after)
    if not effects or not away:
        return model, after, []
    longest = max(episodes, key=lambda e: len(e.config.holes))  # type: ignore[arg-type]
    found = confirm(longest, effects, model, prior, updated_folders[episodes.index(longest)],
                    before, away, out / "confirm", tick, beside, workers)
    dropped = [c.effect for c in found if not c.confirmed]
    if not dropped:
        return model, after, found
    reduced = model
    for name in dropped:
        reduced = without_effect(reduced, name, prior)
    tick(f"dropped {', '.join(dropped)}; the holes once more without")
    path = out / "confirm" / "confirmed.model.json"
    path.write_text(json.dumps(reduced, indent=2))
    folders = rerun(episodes, out / "confirmed", str(path), updated_contact_friction(reduced), tick)
    without = compare(real, outcomes_of(folders))
    why = worse_without(after, without, dropped)
    if not why:
        return reduced, without, found
    return model, after, [dataclasses.replace(c, kept_because=why) if not c.confirmed else c
                          for c in found]


def worse_without(after: dict[str, OutcomeDiff], without: dict[str, OutcomeDiff],
                  dropped: Sequence[str]) -> str:
    """Why the update stays whole though ``dropped`` were not confirmed on a few holes: every
    hole rerun without them leaves more outcomes beyond their interval than the update did
    ("" where it leaves as many or fewer: the drop stands)."""
    n_with, n_without = (sum(beyond_ci(n, d[n]) for n in OUTCOMES) for d in (after, without))
    if n_without <= n_with:
        return ""
    return (f"every hole without {', '.join(dropped)} left {n_without} outcome(s) beyond their "
            f"interval, the update {n_with}")
