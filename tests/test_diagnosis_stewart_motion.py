"""The moving-Stewart domain of ``serpar diagnose``: twins of MuJoCo's platform driven along a
continuous trajectory with one concealed latency each (twins/stewart_motion_twin.py),
diagnosed blind from every sample of commanded and measured legs and motion-capture poses
(diagnosis/stewart_motion*.py)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pyarrow as pa
import pytest
from diagnosis_support import RMS_TARGET, assert_jacobian_matches_differences, run_trials

from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.family import Family
from serpar.diagnosis.fit import fit_model
from serpar.diagnosis.stewart_motion_effects import moving_share
from serpar.diagnosis.stewart_motion_family import AXES, StewartMotionFamily
from serpar.errors import ConfigError, IdentificationError
from serpar.sim.recording import Recording
from serpar.twins.stewart_motion_twin import EFFECTS, make_twin

pytestmark = [pytest.mark.xdist_group("stewart_motion_twins"), pytest.mark.slow]

TRIALS = {"none": 0, "leg_servo_lag": 0, "mocap_latency": 0}
"""Effect -> twin seed (default magnitude): the fixed, seeded set of concealed trials."""
TRUTH_PARAM = {"leg_servo_lag": "tau_servo", "mocap_latency": "tau_mocap"}


@pytest.fixture(scope="module")
def results() -> dict:
    return run_trials(make_twin, TRIALS)


def test_family_implements_the_contract(results) -> None:
    rec, _, fam, _ = results["none"]
    assert isinstance(fam, StewartMotionFamily) and isinstance(fam, Family)
    assert set(EFFECTS) <= {e.name for e in fam.effects}
    assert fam.n_samples == rec.signals.num_rows == 3000
    rows = np.arange(fam.n_samples)
    r = fam.residual({}, rows)
    assert r.shape == (12 * fam.n_samples,) and np.all(np.isfinite(r))
    channels = {row.channel for row in fam.locate(rows, r)}
    assert set(AXES) | {f"leg {i} tracking" for i in range(1, 7)} <= channels


@pytest.mark.parametrize("effect", EFFECTS)
def test_hidden_effect_is_top_ranked(results, effect: str) -> None:
    diag = results[effect][3]
    assert diag.top_effect == effect, [f.effect for f in diag.findings]
    assert len(diag.findings) == 1, diag.verdict


def test_no_effect_says_no_missing_physics(results) -> None:
    diag = results["none"][3]
    assert diag.no_missing_physics, diag.verdict
    assert diag.findings == ()


@pytest.mark.parametrize("effect", list(TRIALS))
def test_heldout_rms_after_fit_near_noise_floor(results, effect: str) -> None:
    diag = results[effect][3]
    assert diag.heldout_rms_after <= RMS_TARGET, diag.heldout_rms_after


@pytest.mark.parametrize("effect", EFFECTS)
def test_latency_recovered_within_3_sigma(results, effect: str) -> None:
    _, answer, _, diag = results[effect]
    (est,) = next(f for f in diag.findings if f.effect == effect).params
    assert est.name == TRUTH_PARAM[effect]
    assert abs(est.value - answer["params"]["tau_s"]) <= 3.0 * est.std, (est, answer)


def test_concealment(results) -> None:
    """Servo lag: the kinematics sees nothing (pose vs measured legs at the noise floor).
    Mocap latency: the slow training motion leaves the pose residual near noise per sample,
    the fast held-out motion shows it; and the rest-hold family never sees either (it finds
    one rest hold in a motion recording and refuses)."""
    fam = results["leg_servo_lag"][2]
    rows = np.arange(fam.n_samples)
    pose = fam.residual({}, rows).reshape(-1, 12)[:, :6]
    assert np.sqrt(np.mean(pose**2)) < 1.05
    fam = results["mocap_latency"][2]
    train, held = fam.split(np.random.default_rng(0))
    r = fam.residual({}, rows).reshape(-1, 12)[:, :6]
    rms_train, rms_held = (float(np.sqrt(np.mean(r[x] ** 2))) for x in (train, held))
    assert rms_train < 1.2 < rms_held, (rms_train, rms_held)
    from serpar.diagnosis.stewart_family import family_from_recording as rest_family

    with pytest.raises(IdentificationError, match="rest holds found"):
        rest_family(results["mocap_latency"][0])


def test_static_candidates_do_not_explain_a_latency(results) -> None:
    fam = results["mocap_latency"][2]
    train, held = fam.split(np.random.default_rng(0))
    lat = fit_model(fam, ("mocap_latency",), train, held)
    for name in ("leg_encoder_offset", "leg_compliance"):
        assert fit_model(fam, (name,), train, held).heldout_chi2 > lat.heldout_chi2 + 100, name


def test_exact_jacobian_matches_differences(results) -> None:
    fam = results["none"][2]
    rows = np.arange(1000, 3000, 37)
    params = {e.name: e.x0 + 0.1 * (e.upper - e.x0) * np.linspace(0.2, 0.5, e.n_params)
              for e in fam.effects if e.name != "stewart_geometry"}
    assert_jacobian_matches_differences(fam, params, rows, rel_step=1e-3, min_step=1e-9,
                                        rtol=2e-2, floor=1e-3)


def test_twin_answer_stays_out_of_the_recording(results) -> None:
    rec, answer, _, _ = results["mocap_latency"]
    text = json.dumps(rec.meta.as_json())
    assert "latency" not in text and "tau" not in text and "delay" not in text
    assert answer["effect"] == "mocap_latency" and answer["params"]["tau_s"] > 0


def test_twin_rejects_unknown_effect_and_bad_magnitude() -> None:
    with pytest.raises(ConfigError, match="unknown Stewart motion effect 'backlash'; valid: "
                                          "leg_servo_lag, mocap_latency"):
        make_twin("backlash", None, 0)
    with pytest.raises(ConfigError, match="magnitude -1.0 for mocap_latency: valid"):
        make_twin("mocap_latency", -1.0, 0)


def test_choose_routes_by_motion(results) -> None:
    """A motion recording goes to the motion family; the same samples with each command held
    for 100 samples look like rest holds and go to the rest-hold family."""
    rec = results["none"][0]
    assert moving_share(rec) > 0.9
    held = rec.signals.take(pa.array(np.repeat(np.arange(0, 3000, 100), 100)))
    assert moving_share(Recording(rec.meta, held)) < 0.05
    with pytest.raises(IdentificationError, match="rest holds found"):
        family_from_recording(Recording(rec.meta, held))


# -- bad input -------------------------------------------------------------------------------

def _edited(rec: Recording, change) -> Recording:
    cols = {c: rec.signals.column(c) for c in rec.signals.column_names}
    meta = rec.meta
    if isinstance(change, str):  # "drop NAME": the channel and its noise sigma
        name = change.split()[1]
        cols.pop(name)
        meta = dataclasses.replace(meta, noise_sigma={k: v for k, v in meta.noise_sigma.items()
                                                      if k != name})
    elif isinstance(change, dict):
        meta = dataclasses.replace(meta, noise_sigma=change)
    else:
        change(cols)
    return Recording(dataclasses.replace(meta, channels=tuple(cols)), pa.table(cols))


def _set(name: str, fn):
    def change(cols):
        cols[name] = pa.array(fn(cols[name].to_numpy().copy()))
    return change


@pytest.mark.parametrize("change,message", [
    ("drop platform_qz", r"motion recording needs channels platform_qz \(valid set: leg_cmd1"),
    ("drop leg4", r"motion recording needs channels leg4 \(valid set"),
    ("drop leg_cmd2", r"needs channels leg_cmd2 \(valid set"),
    ({k: 5e-5 for k in ("platform_x", "platform_y", "platform_z", "platform_qw", "platform_qx",
                        "platform_qy", "platform_qz")}, r"noise_sigma lacks leg1, leg2"),
    (_set("leg2", lambda x: np.where(np.arange(len(x)) == 700, np.nan, x)),
     r"channel leg2 has 1 non-finite sample\(s\) \(NaN/inf\), first at row 700"),
    (_set("leg3", lambda x: x * 1000.0), r"leg3 ranges .* outside the nominal platform's leg"),
    (_set("platform_qx", lambda x: np.where(np.arange(len(x)) == 123, x + 0.1, x)),
     r"platform_qw/qx/qy/qz is not a unit quaternion at row 123"),
])
def test_bad_input_is_one_line_naming_the_problem(results, change, message: str) -> None:
    rec = results["none"][0]
    with pytest.raises(IdentificationError, match=message) as err:
        family_from_recording(_edited(rec, change))
    assert "\n" not in str(err.value)


def test_blind_bench_draws_stewart_motion_trials() -> None:
    from serpar.checks.blind_bench import WRONG, plan

    trials = plan(12, 0, ("stewart_motion",))
    assert {d for d, *_ in trials} == {"stewart_motion"}
    assert {e for _, e, *_ in trials} <= {"none", WRONG, *EFFECTS}
