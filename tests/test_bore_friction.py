"""The bore's friction from the insertions' in-bore push, read through the simulator's reruns at
two mu (diagnosis/bore_friction.py, checks/sim2real_bore.py): synthetic holes whose truth is known."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from serpar.checks.sim2real import NOMINAL_MU
from serpar.checks.sim2real_bore import bore_rerun_mu, with_bore_friction
from serpar.diagnosis.bore_friction import bore_friction
from serpar.diagnosis.task_outcomes import OUTCOMES, HoleOutcome


def _holes(push: np.ndarray) -> list[HoleOutcome]:
    base = dict.fromkeys(OUTCOMES, 0.0)
    return [HoleOutcome(k, k, base, (float(f), 0.05)) for k, f in enumerate(push)]


def _cell(mu: float, n: int = 12, noise: float = 0.1, seed: int = 0) -> np.ndarray:
    """Each hole's wall load N_h (its own misalignment) times mu, plus the chaos of contact."""
    rng = np.random.default_rng(seed)
    wall = np.linspace(2.0, 6.0, n)
    return mu * wall + rng.normal(0.0, noise, n)


def test_mu_is_read_on_the_line_through_two_reruns() -> None:
    real, at_nominal = _cell(0.445, seed=1), _cell(NOMINAL_MU, seed=2)
    mu1, why = bore_rerun_mu(_holes(real), _holes(at_nominal), NOMINAL_MU)
    assert why == "" and mu1 == pytest.approx(NOMINAL_MU + 0.25)  # the cell pushes harder
    found = bore_friction(_holes(real), _holes(at_nominal), _holes(_cell(mu1, seed=3)),
                          NOMINAL_MU, mu1)
    assert found.mu is not None and found.std is not None
    assert abs(found.mu - 0.445) < 2 * found.std and found.std < 0.05 and found.holes == 12
    model, note = with_bore_friction({"effects": ["payload"], "params": {"payload": {}}}, found)
    assert model["effects"] == ["payload", "contact_friction"]
    assert model["params"]["contact_friction"]["values"][0] == pytest.approx(found.mu - NOMINAL_MU)
    assert "in the updated model" in note


def test_a_push_the_simulator_matches_spends_no_rerun() -> None:
    mu1, why = bore_rerun_mu(_holes(_cell(NOMINAL_MU, seed=1)), _holes(_cell(NOMINAL_MU, seed=2)),
                             NOMINAL_MU)
    assert mu1 is None and "agrees with the simulator's" in why
    mu1, why = bore_rerun_mu(_holes(_cell(0.3)[:1]), _holes(_cell(NOMINAL_MU)[:1]), NOMINAL_MU)
    assert mu1 is None and "2 needed" in why


def test_holes_whose_push_does_not_feel_mu_leave_it_not_identifiable() -> None:
    """Journals that slide down the bore's axis touch no wall: mu moves nothing."""
    flat = np.full(8, 0.5)
    found = []
    for seed in range(40):  # a chance false finding at most as often as 3 sigma's level says
        rng = np.random.default_rng(seed)
        found.append(bore_friction(*(_holes(flat + rng.normal(0, 0.1, 8)) for _ in range(3)),
                                   NOMINAL_MU, NOMINAL_MU + 0.25))
    assert sum(f.mu is not None for f in found) <= 1
    assert all("does not load the bore's wall enough" in f.reason for f in found if f.mu is None)
    model, note = with_bore_friction({"effects": [], "params": {}}, found[1])
    assert model == {"effects": [], "params": {}} and note == ""


def test_the_chamfer_slides_estimate_and_the_bores_are_combined_or_kept_apart() -> None:
    real, nominal = _cell(0.4, seed=1), _cell(NOMINAL_MU, seed=2)
    found = bore_friction(_holes(real), _holes(nominal), _holes(_cell(0.45, seed=3)),
                          NOMINAL_MU, 0.45)
    assert found.mu is not None and found.std is not None
    slides = {"effects": ["contact_friction"], "params": {"contact_friction": {
        "values": [found.mu - NOMINAL_MU + found.std], "std": [found.std], "names": ["d_mu"]}}}
    model, note = with_bore_friction(slides, found)
    combined = model["params"]["contact_friction"]
    assert combined["values"][0] == pytest.approx(found.mu - NOMINAL_MU + found.std / 2)
    assert combined["std"][0] == pytest.approx(found.std / np.sqrt(2)) and "with the chamfer" in note
    far = {"effects": ["contact_friction"], "params": {"contact_friction": {
        "values": [found.mu - NOMINAL_MU + 10 * found.std], "std": [found.std], "names": ["d_mu"]}}}
    model, note = with_bore_friction(far, found)
    assert model is far and "keeps the slides'" in note


def test_a_push_the_arm_explains_is_not_read_as_the_bores_friction() -> None:
    """A hand's weight in the axial estimate (+0.08 N, 8 g) on a cell with the nominal mu: the
    push differs from the nominal arm's, and a line through reruns on the nominal arm reads it
    as a mu far above the cell's; on the diagnosed arm (which carries the hand) the line reads
    the nominal mu and nothing is named."""
    hand = 0.08
    real = _cell(NOMINAL_MU, seed=1, noise=0.02) + hand
    nominal_arm = _cell(NOMINAL_MU, seed=2, noise=0.02)
    mu1, why = bore_rerun_mu(_holes(real), _holes(nominal_arm), NOMINAL_MU)
    assert mu1 is not None and why == ""  # the gate sees the difference: a rerun is spent
    wrong = bore_friction(_holes(real), _holes(nominal_arm),
                          _holes(_cell(mu1, seed=3, noise=0.02)), NOMINAL_MU, mu1)
    assert wrong.mu is not None and wrong.mu > NOMINAL_MU + 5 * wrong.std  # what it would name
    found = bore_friction(_holes(real), _holes(_cell(NOMINAL_MU, seed=2, noise=0.02) + hand),
                          _holes(_cell(mu1, seed=3, noise=0.02) + hand), NOMINAL_MU, mu1)
    assert found.mu is None and found.agrees and "within 2 sigma" in found.reason
    model, note = with_bore_friction({"effects": ["payload"], "params": {"payload": {}}}, found)
    assert model["effects"] == ["payload"] and note == ""


def _fake_simulator(monkeypatch: pytest.MonkeyPatch, hand: float) -> list:
    """checks/sim2real_bore.py's reruns replaced by synthetic holes: a rerun on the diagnosed arm
    (a model file) carries the hand's push, a rerun's mu is its contact friction; returns the
    (folder, mu) of every rerun asked for."""
    from serpar.checks import sim2real_bore

    calls: list[tuple[str, float | None]] = []

    def rerun(episodes, out, plant_model, contact_friction, tick):
        out.mkdir(parents=True)
        calls.append((out.name, contact_friction))
        mu = NOMINAL_MU if contact_friction is None else contact_friction
        push = _cell(mu, seed=2 + len(calls), noise=0.02) + (hand if plant_model else 0.0)
        (out / "push.npy").write_bytes(push.tobytes())
        return [out]

    class Ahead:  # the rerun started beside the updated one, run here at once
        def __init__(self, episodes, out, plant_model, contact_friction, tick):
            self.out, self.folders = out, rerun(episodes, out, plant_model, contact_friction, tick)

        def result(self):
            return self.folders

        def cancel(self):
            calls.append(("cancelled", None))
            shutil.rmtree(self.out)

        def stop(self):
            pass

    monkeypatch.setattr(sim2real_bore, "rerun", rerun)
    monkeypatch.setattr(sim2real_bore, "BackgroundRerun", Ahead)
    monkeypatch.setattr(sim2real_bore, "outcomes_of", lambda folders: _holes(
        np.frombuffer((folders[0] / "push.npy").read_bytes())))
    return calls


def _updated_rerun(real_mu: float, hand: float, monkeypatch, out, nominal_mu: float | None = None):
    """``nominal_mu``: the nominal rerun's holes at that mu, no hand (what the rerun started
    beside the updated one guesses from); None: no nominal rerun given."""
    from serpar.checks.sim2real_bore import updated_rerun

    calls = _fake_simulator(monkeypatch, hand)
    real = _holes(_cell(real_mu, seed=1, noise=0.02) + hand)
    model = {"effects": ["payload"], "params": {"payload": {}}}
    nominal = None if nominal_mu is None else _holes(_cell(nominal_mu, seed=9, noise=0.02))
    return calls, *updated_rerun([], real, model, out, lambda line: None, nominal)


def test_a_push_the_updated_rerun_explains_spends_no_second_rerun(monkeypatch, tmp_path) -> None:
    """The diagnosed simulator's rerun (OUT/updated) is the line's first point: a hand's weight
    it carries leaves the push agreeing with the cell's, no rerun at a second mu, no mu named."""
    calls, model, bore, folders, note = _updated_rerun(NOMINAL_MU, 0.08, monkeypatch, tmp_path)
    assert calls == [("updated", None)] and bore.mu is None and bore.agrees
    assert model["effects"] == ["payload"] and note == "" and folders == [tmp_path / "updated"]


def test_a_rougher_bore_gets_its_mu_and_the_holes_once_more(monkeypatch, tmp_path) -> None:
    """A cell at mu 0.445 (and a hand): one rerun at a second mu (OUT/bore_mu) gives mu within
    2 sigma, and the holes run once more with it, the first rerun kept as OUT/bore_mu0."""
    calls, model, bore, folders, note = _updated_rerun(0.445, 0.08, monkeypatch, tmp_path)
    assert [c[0] for c in calls] == ["updated", "bore_mu", "updated"]
    assert bore.mu is not None and abs(bore.mu - 0.445) < 2 * bore.std
    assert calls[2][1] == pytest.approx(bore.mu) and "contact_friction" in model["effects"]
    assert (tmp_path / "bore_mu0" / "push.npy").is_file() and folders == [tmp_path / "updated"]
    assert "in the updated model" in note


def test_the_second_mus_rerun_runs_beside_the_updated_one_where_the_nominal_points_right(
        monkeypatch, tmp_path) -> None:
    """A rougher bore: the nominal rerun's push is short of the cell's as the diagnosed arm's
    is, so the rerun at mu + 0.25 starts before the updated one and is the one used; no rerun
    more than without it."""
    calls, model, bore, folders, note = _updated_rerun(0.445, 0.08, monkeypatch, tmp_path,
                                                       nominal_mu=NOMINAL_MU)
    assert [c[0] for c in calls] == ["bore_mu", "updated", "updated"]
    assert calls[0][1] == pytest.approx(NOMINAL_MU + 0.25)
    assert bore.mu is not None and abs(bore.mu - 0.445) < 2 * bore.std
    assert (tmp_path / "bore_mu" / "push.npy").is_file()


def test_a_second_mus_rerun_not_asked_for_is_cancelled_and_leaves_nothing(monkeypatch,
                                                                          tmp_path) -> None:
    """The nominal arm, without the hand, pushes less than the cell: the rerun beside the
    updated one takes mu + 0.25; the hand the update carries explains the push, so it is
    cancelled and its folder removed."""
    calls, model, bore, folders, note = _updated_rerun(NOMINAL_MU, 0.08, monkeypatch, tmp_path,
                                                       nominal_mu=NOMINAL_MU)
    assert [c[0] for c in calls] == ["bore_mu", "updated", "cancelled"] and bore.agrees
    assert not (tmp_path / "bore_mu").exists() and folders == [tmp_path / "updated"]


def test_a_second_mus_rerun_guessed_the_wrong_way_is_replaced(monkeypatch, tmp_path) -> None:
    """The nominal rerun pushed harder than the cell (mu 0.6 there): the guess is mu - 0.1, but
    the diagnosed arm pushes less than the cell at mu 0.445: that rerun is cancelled and the
    holes run at mu + 0.25."""
    calls, model, bore, folders, note = _updated_rerun(0.445, 0.08, monkeypatch, tmp_path,
                                                       nominal_mu=0.6)
    assert [c[0] for c in calls] == ["bore_mu", "updated", "cancelled", "bore_mu", "updated"]
    assert calls[0][1] == pytest.approx(NOMINAL_MU - 0.1)
    assert calls[3][1] == pytest.approx(NOMINAL_MU + 0.25)
    assert bore.mu is not None and abs(bore.mu - 0.445) < 2 * bore.std
