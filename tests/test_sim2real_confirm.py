"""An established effect stays in sim2real's update only where the rerun confirms it
(checks/sim2real_confirm.py): synthetic holes whose truth is known."""

from __future__ import annotations

import pytest

from serpar.checks.sim2real import OutcomeDiff
from serpar.checks.sim2real_confirm import (
    away_from_cell,
    confirm_holes,
    judge,
    to_confirm,
    without_effect,
    worse_without,
)
from serpar.diagnosis.result import Finding
from serpar.diagnosis.task_outcomes import OUTCOMES, HoleOutcome
from serpar.sim.model_file import DiagnosisModel, ParamBlock


def _holes(**values: list[float]) -> list[HoleOutcome]:
    n = len(next(iter(values.values())))
    return [HoleOutcome(k, k, {**dict.fromkeys(OUTCOMES, 0.0), **{o: v[k] for o, v in values.items()}})
            for k in range(n)]


def _diffs(**given: tuple[float, float]) -> dict[str, OutcomeDiff]:
    out = {n: OutcomeDiff(0.0, 0.01, 12, ()) for n in OUTCOMES}
    out.update({n: OutcomeDiff(d, ci, 12, ()) for n, (d, ci) in given.items()})
    return out


def test_an_effect_that_moves_the_outcomes_toward_the_cell_is_confirmed() -> None:
    before = _diffs(seated_depth=(0.25, 0.05), peak_axial_force=(0.4, 0.1))
    real = _holes(seated_depth=[1.25, 1.26], peak_axial_force=[5.4, 5.5])
    with_it = _holes(seated_depth=[1.249, 1.262], peak_axial_force=[5.41, 5.49])
    without = _holes(seated_depth=[1.0, 1.0], peak_axial_force=[5.0, 5.0])
    c = judge("payload", real, with_it, without, before)
    assert c.confirmed and set(c.moves) == {"seated_depth", "peak_axial_force"}
    assert c.moves["seated_depth"][0] < c.moves["seated_depth"][1]


def test_an_effect_that_moves_them_away_is_dropped_and_one_that_moves_nothing_kept() -> None:
    before = _diffs(misalignment_at_contact=(0.02, 0.01))
    real = _holes(misalignment_at_contact=[0.05, 0.06])
    c = judge("link_inertia", real, _holes(misalignment_at_contact=[0.01, 0.0]),
              _holes(misalignment_at_contact=[0.03, 0.04]), before)
    assert not c.confirmed and "dropped" in c.words()
    same = _holes(misalignment_at_contact=[0.03, 0.04])
    idle = judge("latency", real, same, same, before)
    assert idle.confirmed and idle.moves == {} and "moves no outcome" in idle.words()


def test_only_outcomes_moved_away_and_beyond_their_interval_call_for_a_check() -> None:
    before = _diffs(seated_depth=(-0.070, 0.02), peak_axial_force=(0.40, 0.1))
    after = _diffs(seated_depth=(-0.122, 0.02), peak_axial_force=(0.02, 0.1))
    assert away_from_cell(before, after) == ["seated_depth"]
    assert away_from_cell(before, _diffs(seated_depth=(-0.08, 0.2))) == []  # within its CI


def test_a_correction_is_taken_back_to_the_prior_and_a_new_effect_out() -> None:
    prior = DiagnosisModel("cell.yaml", "config", "arm_dynamics", ("joint_friction",), (
        ("joint_friction", ParamBlock(("Fc1",), (0.1,), (0.0,))),))
    model = {"effects": ["joint_friction", "payload"], "params": {
        "joint_friction": {"values": [0.3], "std": [0.01], "names": ["Fc1"]},
        "payload": {"values": [0.2], "std": [0.001], "names": ["mass"]}}}
    back = without_effect(model, "joint_friction", prior)
    assert back["effects"] == ["joint_friction", "payload"]
    assert back["params"]["joint_friction"]["values"] == pytest.approx([0.1])
    gone = without_effect(model, "payload", prior)
    assert gone["effects"] == ["joint_friction"] and "payload" not in gone["params"]
    assert model["effects"] == ["joint_friction", "payload"]  # the update itself is untouched


def test_the_carried_one_of_an_a_or_b_pair_is_confirmed_too() -> None:
    """The update carries a payload it could not tell from the last link's mass: the rerun must
    bear it out like an established effect; a suspected effect the model does not carry is not
    rerun, nor is the bore's friction twice."""
    payload = Finding(2, "payload", "", (), 0.3, -10.0, 10.0, established=False,
                      reasons=("payload or link_inertia: these data cannot tell",))
    link = Finding(3, "link_inertia", "", (), 0.1, -5.0, 5.0, established=False)
    latency = Finding(1, "latency", "", (), 0.5, -20.0, 20.0)
    assert to_confirm(["latency"], 0.41, [latency, payload, link], ["latency", "payload"]) == \
        ["latency", "contact_friction", "payload"]
    assert to_confirm(["contact_friction"], 0.41, [payload], []) == ["contact_friction"]


def test_only_the_outcomes_the_update_moved_away_are_judged() -> None:
    """The update left the insertion's time from contact to seated further from the cell: an
    effect is judged on that outcome alone, not on a grasp the two holes happen to differ in."""
    before = _diffs(contact_to_seated=(0.005, 0.006), seated=(-0.5, 0.33))
    real = _holes(contact_to_seated=[0.678, 0.679], seated=[1.0, 1.0])
    with_it = _holes(contact_to_seated=[0.679, 0.678], seated=[0.0, 0.0])
    without = _holes(contact_to_seated=[0.671, 0.672], seated=[1.0, 1.0])
    assert not judge("stribeck_friction", real, with_it, without, before).confirmed
    c = judge("stribeck_friction", real, with_it, without, before, ["contact_to_seated"])
    assert c.confirmed and set(c.moves) == {"contact_to_seated"}


def test_the_holes_rerun_are_ones_both_seated_where_an_insertion_outcome_is_judged() -> None:
    real = _holes(seated=[1.0, 1.0, 0.0, 1.0, 1.0, 1.0])
    updated = _holes(seated=[0.0, 0.0, 1.0, 1.0, 0.0, 1.0])
    assert confirm_holes(real, updated, ["contact_to_seated"]) == [3, 5]
    assert confirm_holes(real, updated, ["seated"]) == [0, 1]  # every hole has a seated outcome
    assert confirm_holes(real, _holes(seated=[0.0] * 6), ["seated_depth"]) == [0, 1]  # none: the first


def test_a_drop_that_leaves_more_outcomes_outside_is_undone() -> None:
    """Rerun on every hole without the unconfirmed effects, the outcomes went further: the few
    holes that judged each effect are outweighed and the update stays whole."""
    after = _diffs(contact_to_seated=(-0.009, 0.006))
    nominal_like = _diffs(seated=(-0.5, 0.33), seated_depth=(0.34, 0.01),
                          peak_lateral_force=(0.87, 0.02))
    why = worse_without(after, nominal_like, ["payload", "armature"])
    assert "3 outcome(s)" in why and "the update 1" in why
    assert worse_without(after, _diffs(), ["payload"]) == ""  # fewer outside: the drop stands
