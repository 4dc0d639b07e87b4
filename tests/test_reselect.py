"""A selected effect that fails the judging rules after winning its step by a hair is selected
again without (diagnosis/reselect.py): which effects are barred."""

from __future__ import annotations

from serpar.diagnosis.reselect import NEAR_TIE, passed_over
from serpar.diagnosis.result import CandidateScore


def _score(step: int, effect: str, rms: float, earns: bool = True) -> CandidateScore:
    return CandidateScore(step, effect, 7, -100.0, 100.0, rms, earns)


STEPS = [_score(1, "sigmoid_friction", 55.2), _score(1, "payload", 73.0),
         _score(2, "link_inertia", 37.40), _score(2, "payload", 37.73),
         _score(2, "encoder_offset", 44.6), _score(3, "joint_friction", 11.7)]
"""The seed-0 cell's selection: the last link's mass won step 2 from the payload by 0.9 %."""


def test_a_failed_effect_that_won_its_step_by_a_hair_is_barred_naming_its_rival() -> None:
    chosen = ("sigmoid_friction", "link_inertia", "joint_friction")
    assert passed_over(chosen, STEPS, ["link_inertia"]) == {"link_inertia": "payload"}


def test_no_bar_where_the_effect_held_up_or_won_clearly_or_the_rival_did_not_earn() -> None:
    chosen = ("sigmoid_friction", "link_inertia", "joint_friction")
    assert passed_over(chosen, STEPS, []) == {}
    assert passed_over(chosen, STEPS, ["sigmoid_friction"]) == {}  # payload 32 % behind
    far = [s if s.effect != "payload" or s.step != 2 else _score(2, "payload", 37.40 * NEAR_TIE * 1.01)
           for s in STEPS]
    assert passed_over(chosen, far, ["link_inertia"]) == {}
    idle = [s if s.effect != "payload" or s.step != 2 else _score(2, "payload", 37.5, earns=False)
            for s in STEPS]
    assert passed_over(chosen, idle, ["link_inertia"]) == {}
