"""The blind bench's draws and scoring (checks/blind_bench.py): trial kinds, candidates
withheld from the library as outside trials, and an in-library effect whose physics the
library splits over two candidates."""

from __future__ import annotations

import pytest

from serpar.checks.blind_bench import KINDS, WITHHELD, WRONG, blind_bench, plan, run_trial
from serpar.errors import ConfigError
from serpar.twins import arm_dynamics_twin, stewart_twin


def test_kinds_filter_the_draws_and_library_only_is_their_alias() -> None:
    outside = plan(40, 0, ("stewart", "arm_dynamics"), kinds=("outside",))
    allowed = ({e + WITHHELD for e in stewart_twin.WITHHELD + arm_dynamics_twin.WITHHELD}
               | set(arm_dynamics_twin.OUT_OF_LIBRARY))
    assert {e for _, e, *_ in outside} == allowed  # 40 draws over 6 choices: all seen
    quiet = plan(30, 1, ("stewart",), kinds=("none", "wrong_sigma"))
    assert {e for _, e, *_ in quiet} == {"none", WRONG}
    assert plan(60, 2, ("stewart", "arm_dynamics"), library_only=True) == plan(
        60, 2, ("stewart", "arm_dynamics"), kinds=("effect", "none", "wrong_sigma"))
    every = plan(200, 3, ("arm_dynamics",))
    assert any(e.endswith(WITHHELD) for _, e, *_ in every)
    assert all(not e.endswith(WITHHELD) for _, e, *_ in plan(200, 3, ("arm_dynamics",),
                                                              library_only=True))


@pytest.mark.parametrize("kinds,domains,message", [
    (("bogus",), ("stewart",), "unknown trial kind.*valid: effect, outside, none, wrong_sigma"),
    (("outside",), ("stewart_motion",), "no trial of kind"),
])
def test_bad_kinds_are_one_line(kinds, domains, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        plan(3, 0, domains, kinds=kinds)
    assert set(KINDS) == {"effect", "outside", "none", "wrong_sigma"}


@pytest.mark.slow
def test_a_withheld_candidate_makes_an_outside_trial() -> None:
    """One leg's encoder scale with leg_encoder_scale out of the library: scored on the empirical
    term (its leg and stroke), nothing but the leg's constant offset may be established."""
    t = run_trial(0, "stewart", "leg_encoder_scale" + WITHHELD, 0.002, 1)
    assert t.error is None and t.kind == "outside" and t.outside
    assert t.correct, (t.established, t.characterised, t.verdict)
    assert t.characterised[0] == "leg 6 / stroke 6 / proportional"
    assert not t.wrong_finding and t.empirical_rms is not None and t.empirical_rms < 1.5


@pytest.mark.slow
def test_stribeck_friction_is_right_after_its_coulomb_part() -> None:
    """In the library, Stribeck friction is established after joint friction (its Coulomb and
    viscous levels): a right answer, and joint friction is no wrong finding."""
    t = run_trial(0, "arm_dynamics", "stribeck_friction", 0.97, 0)
    assert t.error is None and t.kind == "effect"
    assert t.established[:2] == ("joint_friction", "stribeck_friction"), t.verdict
    assert t.correct and not t.wrong_finding


def test_an_a_or_b_trial_is_neither_right_nor_wrong() -> None:
    """A hidden effect reported as one side of "A or B: these data cannot tell" is counted
    apart and left out of its kind's share; a wrong name still counts against it."""
    from serpar.checks.blind_bench import Trial, _a_or_b_holds
    from serpar.checks.blind_bench_summary import summarise
    from serpar.diagnosis.result import Finding

    def trial(correct: bool, undecided: bool = False) -> Trial:
        return Trial(0, 0, "arm_dynamics", "payload", 1.0, None, "", correct, 1.0, 1.0,
                     undecided=undecided)

    rows = summarise([trial(True), trial(False, undecided=True), trial(False)])["rows"]
    assert rows["effect"]["a_or_b"] == 1 and rows["effect"]["correct"] == 0.5
    reason = ("link_inertia or payload (unmodelled payload): these data cannot tell (...); "
              "the model carries link_inertia")
    f = Finding(1, "link_inertia", "", (), 0.5, -10.0, 10.0, established=False, reasons=(reason,))
    assert _a_or_b_holds((f,), "payload") and _a_or_b_holds((f,), "link_inertia")
    assert not _a_or_b_holds((f,), "armature")


def test_workers_run_the_same_trials_and_keep_their_order() -> None:
    """Two trials in two worker processes score as they do one after the other (the trials are
    drawn before any runs; only the wall times differ), and no worker is no bench."""
    one = blind_bench(2, 5, ("arm_static",), library_only=True)
    two = blind_bench(2, 5, ("arm_static",), library_only=True, workers=2)
    strip = [{k: v for k, v in t.as_dict().items() if k != "diagnosis_s"} for t in one]
    assert [t.index for t in two] == [0, 1]
    assert [{k: v for k, v in t.as_dict().items() if k != "diagnosis_s"} for t in two] == strip
    with pytest.raises(ConfigError, match="--workers 0: must be >= 1"):
        blind_bench(2, 5, ("arm_static",), workers=0)
