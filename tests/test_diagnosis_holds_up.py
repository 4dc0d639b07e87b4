"""A finding must hold up (diagnosis/stability.py) and the residual must be described honestly
(diagnosis/residual.py): admissible parameters, none pinned on a search bound, needed again on
resampled folds, material; a data-based noise estimate that tells an optimistic stated sigma
from a structured residual. Synthetic families whose truth is known, twins, and panda_1."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from test_diagnosis_engine import SIGMA, Line

from serpar.diagnosis import Effect
from serpar.diagnosis.arm_dynamics_effects import EFFECTS
from serpar.diagnosis.arm_static_family import family_from_data
from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.residual import consecutive_noise_ratio
from serpar.diagnosis.select import diagnose
from serpar.diagnosis.stability import Resampled
from serpar.twins.registry import make_twin

PANDA_1 = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "panda_1"


class NoisyLine(Line):
    """Line whose noise is ``factor`` times the stated SIGMA, with a data-based noise
    estimate (sample-to-sample differences) as the time-series families have."""

    def __init__(self, truth: dict[str, float], seed: int, factor: float = 1.0,
                 effects: tuple[Effect, ...] | None = None) -> None:
        super().__init__(truth, seed)
        extra = np.random.default_rng(seed + 100).normal(size=self.y.size)
        self.y = self.y + np.sqrt(max(factor**2 - 1.0, 0.0)) * SIGMA * extra
        if effects is not None:
            self.effects = effects

    def noise_ratio(self, rows, whitened):
        r = consecutive_noise_ratio(rows, whitened, 1)
        return None if r is None else (r, "sample-to-sample differences")


def _slope(lower: float, upper: float, physical_lower: bool = False) -> Effect:
    return Effect("slope", "linear drift", ("slope",), ("m/s",), np.zeros(1), np.full(1, lower),
                  np.full(1, upper), physical_lower=physical_lower)


def test_a_real_effect_is_established_and_needed_on_every_fold() -> None:
    d = diagnose(NoisyLine({"slope": 0.02}, seed=0))
    f = d.findings[0]
    assert f.effect == "slope" and f.established and f.reasons == ()
    assert f.stability == 1.0
    assert d.model["effects"] == ["slope"] and d.top_effect == "slope"
    assert abs(f.params[0].value - 0.02) < 3 * f.params[0].std
    assert d.residual is not None and d.residual.passes
    assert "consistent with the stated noise" in d.verdict


def test_a_spurious_selection_under_optimistic_sigma_is_not_established() -> None:
    """Noise 3x the stated sigma: the forward selection keeps a sine (seed 2) that the folds
    do not need; it is only suspected, the model file holds nothing, and the residual is
    called noise with an optimistic stated sigma."""
    d = diagnose(NoisyLine({}, seed=2, factor=np.sqrt(10.0)))
    assert [f.effect for f in d.findings] == ["sine"]
    f = d.findings[0]
    assert not f.established and f.stability is not None and f.stability < 0.8
    assert any("resampled folds" in r for r in f.reasons)
    assert d.top_effect is None and d.model["effects"] == []
    assert d.verdict.startswith("no finding holds up; suspected, not established: oscillation")
    check = d.residual
    assert check is not None and not check.passes and check.structured is False
    assert 2.8 < check.noise_ratio < 3.6
    assert "optimistic by 3" in check.words and "not missing physics" in check.words


def test_a_structured_residual_is_named_as_such() -> None:
    """A quadratic drift with no quadratic candidate: the slope takes part of it, a structured
    residual remains well above the data's own noise (which is the stated one)."""
    fam = NoisyLine({"curv": 0.003}, seed=1,
                    effects=(_slope(-1.0, 1.0),))
    d = diagnose(fam)
    check = d.residual
    assert check is not None and not check.passes and check.structured is True
    assert 0.85 < check.noise_ratio < 1.2
    assert "structured residual remains" in d.verdict


def test_an_effect_pinned_on_its_search_bound_is_only_suspected() -> None:
    """The drift is 0.05 m/s but the candidate allows +-0.02: the fit sits on the bound with a
    small sigma, so the candidate cannot be what the data show."""
    d = diagnose(NoisyLine({"slope": 0.05}, seed=0, effects=(_slope(-0.02, 0.02),)))
    f = d.findings[0]
    assert f.effect == "slope" and not f.established
    assert any(r.startswith("pinned on its search bound: slope = 0.02") for r in f.reasons)
    assert d.model["effects"] == []
    assert d.verdict.startswith("no finding holds up")


def test_an_inadmissible_value_is_never_fitted() -> None:
    """A drift that only a negative 'friction' could explain: fitted under the physical bound,
    the candidate cannot follow it and is not found; the residual is called structured."""
    d = diagnose(NoisyLine({"slope": -0.02}, seed=0, effects=(_slope(0.0, 1.0, True),)))
    assert d.established == ()
    assert all(p.value >= 0 for f in d.findings for p in f.params)
    assert d.residual is not None and d.residual.structured is True


class GhostLine(NoisyLine):
    """The drift effect carries a second parameter whose regressor is 1e-4 of a fast sine: the
    data cannot identify it, and least squares throws it onto a bound."""

    def __init__(self, seed: int) -> None:
        two = Effect("slope", "linear drift", ("slope", "ghost"), ("m/s", "m"), np.zeros(2),
                     np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
        super().__init__({"slope": 0.02}, seed, effects=(two,))

    def residual(self, params, rows):
        r = super().residual({k: v[:1] for k, v in params.items()}, rows)
        if "slope" in params:
            r = r + params["slope"][1] * 1e-4 * np.sin(137.0 * self.t[rows]) / SIGMA
        return r


def test_a_parameter_the_data_do_not_identify_is_held_at_zero() -> None:
    d = diagnose(GhostLine(seed=0))
    f = d.findings[0]
    assert f.established and "not identified by these data, held at 0: ghost" in f.note
    assert [p.name for p in f.params] == ["slope"]
    assert d.model["params"]["slope"]["values"][1] == pytest.approx(0.0, abs=1e-9)


def test_arm_dynamics_twin_with_optimistic_sigma_is_noise_not_physics() -> None:
    rec, _ = make_twin(None, None, seed=3, domain="arm_dynamics", sigma_error=2.0)
    d = diagnose(family_from_recording(rec), 3)
    assert d.established == ()
    check = d.residual
    assert check is not None and not check.passes and check.structured is False
    assert 1.7 < check.noise_ratio < 2.3
    assert "stated sigma is optimistic" in d.verdict


def test_arm_dynamics_twin_friction_leaves_noise_at_the_stated_sigma() -> None:
    rec, _ = make_twin("joint_friction", None, seed=3)
    d = diagnose(family_from_recording(rec), 3)
    assert d.top_effect == "joint_friction" and d.findings[0].stability == 1.0
    fc = [p for p in d.findings[0].params if p.name.startswith(("Fc", "Fv"))]
    assert fc and all(p.value >= 0 for p in fc)
    assert d.residual is not None and d.residual.passes
    assert 0.9 < d.residual.noise_ratio < 1.1


def test_a_negative_value_is_said_as_a_nominal_model_excess() -> None:
    """An effect whose negative first parameter is something the nominal model has and the
    machine lacks (the payload: mass the model carries at the flange) says so in words."""
    payload = next(e for e in EFFECTS if e.name == "payload")
    assert "{value}" in payload.excess_words
    drift = replace(_slope(-1.0, 1.0), excess_words="the model drifts {value} faster than the data")
    d = diagnose(NoisyLine({"slope": -0.02}, seed=0, effects=(drift,)))
    f = d.findings[0]
    assert f.established and f.params[0].value < 0
    assert f.note.startswith("the model drifts 0.020") and f.note.endswith("m/s faster than the data")
    assert f.note in f.words()


@pytest.mark.slow
@pytest.mark.skipif(not PANDA_1.is_dir(), reason="needs ../shared/realdata/panda_1")
def test_panda_1_findings_hold_across_seeds_and_held_out_placements() -> None:
    """Seeds 0, 1, 2 and 11 hold out each of the three tool placements (right, front, right,
    back-high): the established effects and the dominant geometric errors must not change
    with the split."""
    from serpar.calibration.arm_static_data import panda_folder_data

    data = panda_folder_data(str(PANDA_1))
    held, found, j4 = set(), [], []
    for seed in (0, 1, 2, 11):
        fam = family_from_data(data)
        _, rows = fam.split(np.random.default_rng(seed))
        held.add(str(data.placement[rows[0]]))
        d = diagnose(family_from_data(data), seed)
        found.append(tuple(f.effect for f in d.established))
        g = next(f for f in d.findings if f.effect == "geometric")
        j4.append(next(p for p in g.params if p.name == "j4.theta"))
    assert held == {"front", "right", "back-high"}
    assert len(set(found)) == 1 and found[0][0] == "geometric"
    values = np.array([p.value for p in j4])
    assert np.ptp(values) < 3 * max(p.std for p in j4)
    assert np.all((-0.025 < values) & (values < -0.020))


def test_twin_sigma_error_is_validated() -> None:
    from serpar.errors import ConfigError

    with pytest.raises(ConfigError, match="sigma_error"):
        make_twin(None, None, 0, "arm_dynamics", sigma_error=0.0)
    rec, answer = make_twin(None, None, 0, "stewart", sigma_error=2.0)
    base, _ = make_twin(None, None, 0, "stewart")
    assert answer["stated_sigma_optimistic_by"] == 2.0
    k = next(iter(base.meta.noise_sigma))
    assert rec.meta.noise_sigma[k] == pytest.approx(base.meta.noise_sigma[k] / 2)
    assert replace(rec.meta, noise_sigma=base.meta.noise_sigma) == base.meta
    static, _ = make_twin(None, None, 0, "arm_static", sigma_error=2.0)
    nominal, _ = make_twin(None, None, 0, "arm_static")
    assert (static.meta.model["measurements"]["sigma_m"]
            == pytest.approx(nominal.meta.model["measurements"]["sigma_m"] / 2))


def test_the_folds_give_a_jackknife_standard_error() -> None:
    """sqrt((k-1)/k * sum of squared deviations): for 1..5 that is sqrt(8), where the plain
    spread of the fold estimates (std, ddof 1) is 1.58."""
    r = Resampled("e", 5, 5, np.arange(1.0, 6.0)[:, None], True)
    assert r.jackknife_std[0] == pytest.approx(np.sqrt(8.0))
    assert Resampled("e", 1, 1, np.ones((1, 2)), True).jackknife_std.tolist() == [0.0, 0.0]
