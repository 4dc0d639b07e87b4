"""An established effect stays in ``serpar sim2real``'s updated model only if the updated rerun
confirms it: the outcomes it moves move toward the real cell.

One rerun of every hole with the whole update shows what the update did, not what each effect
did. Where that rerun leaves some outcome further from the cell than the nominal simulator did
(and beyond its interval), each established effect is taken out in turn and the first
:data:`CONFIRM_HOLES` holes of the diagnosed recording rerun without it: on those holes the
effect's own move of every outcome is the updated rerun's minus that one. An effect is
confirmed when the outcomes it moves (beyond what they are measured to) end, in sum, nearer the
cell with it than without it, each outcome's distance in units of its interval before the
update; an effect that does not is dropped, and the holes are rerun once more without the
dropped ones (the update's last rerun).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

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
"""Holes rerun without each effect: the first of the diagnosed recording."""
MOVED = 1e-9
"""An outcome an effect moves by less than this (beyond its resolution) is not moved by it."""


@dataclass(frozen=True)
class Confirmation:
    effect: str
    confirmed: bool
    moves: dict[str, tuple[float, float]]
    """Outcome -> (mean |real - sim| with the effect, without it) over the rerun holes."""

    def words(self) -> str:
        shown = ", ".join(f"{n} {w:.3g} with / {wo:.3g} without" for n, (w, wo) in self.moves.items())
        verdict = "confirmed" if self.confirmed else "dropped: it moves the outcomes away from the cell"
        return f"{self.effect} {verdict} ({shown or 'it moves no outcome on these holes'})"

    def as_dict(self) -> dict[str, object]:
        return {"effect": self.effect, "confirmed": self.confirmed,
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
          without: list[HoleOutcome], before: dict[str, OutcomeDiff]) -> Confirmation:
    """Whether effect ``name`` moves the outcomes of the rerun holes toward the cell."""
    r, w, wo = _by_hole(real), _by_hole(with_it), _by_hole(without)
    keys = [k for k in wo if k in r and k in w]
    moves: dict[str, tuple[float, float]] = {}
    net = 0.0
    for o in OUTCOMES:
        trio = np.array([(r[k][o], w[k][o], wo[k][o]) for k in keys], float)
        trio = trio[np.all(np.isfinite(trio), axis=1)]
        if not trio.size or np.abs(trio[:, 1] - trio[:, 2]).max() <= RESOLUTION.get(o, 0.0) + MOVED:
            continue
        near, far = np.abs(trio[:, 0] - trio[:, 1]).mean(), np.abs(trio[:, 0] - trio[:, 2]).mean()
        moves[o] = (float(near), float(far))
        scale = max(before[o].ci or 0.0, RESOLUTION.get(o, 0.0), abs(before[o].diff or 0.0), 1e-12)
        net += (near - far) / scale
    return Confirmation(name, net <= 0.0, moves)


def confirm(longest: RealEpisode, effects: list[str], model: dict[str, object],
            prior: DiagnosisModel, updated_folder: Path, before: dict[str, OutcomeDiff],
            out: Path, tick: Tick) -> list[Confirmation]:
    """Each of ``effects`` judged on the first holes of ``longest`` rerun without it."""
    holes = tuple(longest.config.holes)[:CONFIRM_HOLES]  # type: ignore[arg-type]
    sample = dataclasses.replace(longest, config=dataclasses.replace(longest.config, holes=holes))
    real = outcomes_of([longest.folder])[:len(holes)]
    with_it = outcomes_of([updated_folder])[:len(holes)]
    out.mkdir(parents=True, exist_ok=True)
    found = []
    for name in effects:
        reduced = without_effect(model, name, prior)
        path = out / f"without_{name}.model.json"
        path.write_text(json.dumps(reduced, indent=2))
        tick(f"confirming {name}: {len(holes)} hole(s) without it")
        folders = rerun([sample], out / f"without_{name}", str(path),
                        updated_contact_friction(reduced), tick)
        found.append(judge(name, real, with_it, outcomes_of(folders), before))
    return found


def away_from_cell(before: dict[str, OutcomeDiff], after: dict[str, OutcomeDiff]) -> list[str]:
    """Outcomes the update moved further from the cell (beyond their resolution) and left
    beyond their interval."""
    return [n for n in OUTCOMES if before[n].diff is not None and after[n].diff is not None
            and abs(after[n].diff) > abs(before[n].diff) + RESOLUTION.get(n, 0.0)  # type: ignore[arg-type]
            and beyond_ci(n, after[n])]


def confirmed_update(episodes: list[RealEpisode], real: list[HoleOutcome],
                     before: dict[str, OutcomeDiff], after: dict[str, OutcomeDiff],
                     updated_folders: list[Path], model: dict[str, object], prior: DiagnosisModel,
                     effects: list[str], out: Path, tick: Tick
                     ) -> tuple[dict[str, object], dict[str, OutcomeDiff], list[Confirmation]]:
    """Where the updated rerun left an outcome further from the cell, each of ``effects``
    judged by :func:`confirm`; the unconfirmed dropped and every hole rerun once more without
    them. Returns the model, the outcomes' differences after, and the judgements."""
    if not effects or not away_from_cell(before, after):
        return model, after, []
    longest = max(episodes, key=lambda e: len(e.config.holes))  # type: ignore[arg-type]
    found = confirm(longest, effects, model, prior, updated_folders[episodes.index(longest)],
                    before, out / "confirm", tick)
    dropped = [c.effect for c in found if not c.confirmed]
    if not dropped:
        return model, after, found
    for name in dropped:
        model = without_effect(model, name, prior)
    tick(f"dropped {', '.join(dropped)}; the holes once more without")
    path = out / "confirm" / "confirmed.model.json"
    path.write_text(json.dumps(model, indent=2))
    folders = rerun(episodes, out / "confirmed", str(path), updated_contact_friction(model), tick)
    return model, compare(real, outcomes_of(folders)), found
