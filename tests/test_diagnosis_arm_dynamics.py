"""The arm-dynamics domain of ``serpar diagnose``: twins with one concealed effect each, made
by MuJoCo forward dynamics (twins/arm_dynamics_twin.py), diagnosed blind by the nominal
model's inverse dynamics (diagnosis/arm_dynamics*.py).

Fixed seed 0, 10 s twins (the CLI's default is 20 s) so the file runs in under a minute.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pyarrow as pa
import pytest
from scipy.interpolate import CubicSpline

from serpar.diagnosis import separable as separable_fit
from serpar.diagnosis.arm_dynamics_effects import EXTENT_START, EffectModels
from serpar.diagnosis.arm_dynamics_family import (
    CHANNELS,
    ArmDynamicsConfig,
    family_from_recording,
)
from serpar.diagnosis.arm_dynamics_payload import (
    link_rate,
    payload_inertial,
    payload_model,
    set_payload,
)
from serpar.diagnosis.family import Family
from serpar.diagnosis.fit import earns, fit_model
from serpar.diagnosis.forward import at_noise_floor
from serpar.diagnosis.select import diagnose
from serpar.errors import ConfigError, IdentificationError
from serpar.sim import channels as ch
from serpar.sim.plants.arm_changes import inertia_from_extent, inertia_problem
from serpar.sim.recording import Recording
from serpar.twins.arm_dynamics_twin import DECLARED, EFFECTS, OUT_OF_LIBRARY, make_twin

IN_LIBRARY = tuple(e for e in EFFECTS if e not in OUT_OF_LIBRARY)
"""The twin effects the candidate library holds (the others: tests/test_diagnosis_empirical.py)."""
SINGLE = tuple(e for e in IN_LIBRARY if e != "stribeck_friction")
"""The ones one candidate alone explains (Stribeck friction is Coulomb + viscous + its fall:
two candidates, tested on its own below)."""

SEED = 0
DURATION = 10.0
_CACHE: dict[str | None, tuple] = {}


def twin(effect: str | None):
    """(recording, answer, family, train rows, held-out rows, baseline fit), built once."""
    if effect not in _CACHE:
        rec, answer = make_twin(effect, None, SEED, duration=DURATION)
        fam = family_from_recording(rec)
        train, held = fam.split(np.random.default_rng(SEED))
        _CACHE[effect] = (rec, answer, fam, train, held, fit_model(fam, (), train, held))
    return _CACHE[effect]


_FITS: dict[str | None, dict] = {}


def single_fits(effect: str | None):
    """Every candidate fitted alone (with the baseline) on the twin of `effect`, once."""
    if effect not in _FITS:
        _, _, fam, train, held, base = twin(effect)
        _FITS[effect] = {e.name: fit_model(fam, (e.name,), train, held, base.params)
                         for e in fam.effects}
    return _FITS[effect]


def test_the_jacobian_is_the_fits_own_differences_with_exact_tares() -> None:
    """The family's Jacobian (diagnosis/arm_dynamics_jacobian.py) against scipy's 2-point
    differences of its residual: the non-linear effects' columns equal, the tares', the
    linear effects' (exact: friction through its stiction band, rotor inertia), the sigmoid
    friction's, the Stribeck fall's and the payload's (analytic, the payload's through the
    rows' sigma too) within the differences' own error; a wrong sign or a dropped stiction band
    would be ~100 % off."""
    from scipy.optimize._numdiff import approx_derivative

    _, _, fam, train, _, _ = twin("joint_friction")
    by_name = {e.name: e for e in fam.effects}
    rng = np.random.default_rng(3)
    params = {fam.baseline.name: rng.normal(0.0, 0.05, fam.baseline.n_params),
              "joint_friction": by_name["joint_friction"].x0 + 0.2,
              "armature": by_name["armature"].x0 + 0.05,
              "sigmoid_friction": by_name["sigmoid_friction"].x0 + np.r_[np.full(7, 0.3),
                                                                        np.linspace(-3, 5, 7),
                                                                        np.linspace(-.03, .04, 7)],
              "stribeck_friction": np.r_[np.linspace(0.1, 0.4, 7), np.linspace(0.021, 0.17, 7)],
              "payload": by_name["payload"].x0 + 0.01, "latency": np.array([0.002])}
    sizes = {k: v.size for k, v in params.items()}

    def fun(x: np.ndarray) -> np.ndarray:
        out, k = {}, 0
        for name, n in sizes.items():
            out[name], k = x[k:k + n], k + n
        return fam.residual(out, train)

    want = approx_derivative(fun, np.concatenate(list(params.values())), method="2-point")
    got = fam.jacobian(params, train)
    n_exact = (sizes[fam.baseline.name] + sizes["joint_friction"] + sizes["armature"]
               + sizes["sigmoid_friction"] + sizes["stribeck_friction"] + sizes["payload"])
    # the payload's torque is cubic in its parameters: 2-point differences are ~1e-6 off it,
    # central ones ~1e-9 (measured)
    x = np.concatenate(list(params.values()))
    first = n_exact - sizes["payload"]
    want[:, first:n_exact] = approx_derivative(
        lambda p: fun(np.r_[x[:first], p, x[n_exact:]]), x[first:n_exact], method="3-point")
    np.testing.assert_array_equal(got[:, n_exact:], want[:, n_exact:])
    scale = np.abs(want[:, :n_exact]).max(axis=0)
    assert np.all(np.abs(got[:, :n_exact] - want[:, :n_exact]).max(axis=0) < 1e-6 * scale)


class _JointFit:
    """A family without ``baseline_columns``: fit_model fits its tares with the effects."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.kind, self.effects, self.n_samples = inner.kind, inner.effects, inner.n_samples
        self.baseline, self.residual, self.jacobian = inner.baseline, inner.residual, inner.jacobian


@pytest.mark.parametrize("dense_columns", [0, separable_fit.DENSE_COLUMNS])
def test_the_separable_fit_lands_where_the_joint_fit_does(dense_columns: int,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """Variable projection (diagnosis/separable.py: tares solved out at every evaluation) against
    the joint fit of tares and effects, on a drifting tare of 2-s knots: the same chi-square to
    1e-8, the payload's parameters within 1 % of their sigma, the same sigma to 0.1 %. A projection
    that forgot the tare's columns would give the payload another mass and a smaller sigma. Both
    ways of solving the tare's normal equations: sparse (every baseline) and dense (a small one)."""
    monkeypatch.setattr(separable_fit, "DENSE_COLUMNS", dense_columns)
    rec, _, _, _, _, _ = twin("payload")
    fam = family_from_recording(rec, ArmDynamicsConfig(tare_knot_s=2.0))
    train, held = fam.split(np.random.default_rng(SEED))
    assert fam.baseline.n_params > 30
    joint = fit_model(_JointFit(fam), ("payload",), train, held)
    separable = fit_model(fam, ("payload",), train, held)
    assert separable.train_chi2 == pytest.approx(joint.train_chi2, rel=1e-8)
    sigma = joint.std["payload"]
    assert np.all(np.abs(separable.params["payload"] - joint.params["payload"]) < 1e-2 * sigma)
    np.testing.assert_allclose(separable.std["payload"], sigma, rtol=1e-3)
    np.testing.assert_allclose(separable.std[fam.baseline.name], joint.std[fam.baseline.name],
                               rtol=1e-3, atol=1e-12)


def test_a_late_sensor_reads_the_payloads_torque_late_too() -> None:
    """The torque sensors read the whole link torque late, a payload's part included: the
    lag's contribution moves the nominal *and* the payload's torque (the payload's by minus
    the lag times its rate). Against the payload's torque delayed exactly (interpolated at t - lag at every
    sample, windowed like the channel), the contribution's payload part is within 5 % of it
    (2.6 %: the reference's own interpolation between 1 kHz samples, and the second order);
    with the nominal rate alone it would be missing (100 % off), which biased a 0.71 ms lag
    by +15 us with 0.125 kg on the hand (a 12-hole concealed cell)."""
    _, _, fam, train, _, _ = twin("payload")
    t, models = fam.terms, fam._models
    params = np.r_[0.3, 0.01, -0.01, 0.04, EXTENT_START]
    dyn, body = payload_model()
    set_payload(dyn.model, body, payload_inertial(params))
    torque = dyn.link_torque(t.q_full, t.dq_full, t.a_full)
    time = np.arange(len(torque)) / t.rate
    lag = 0.0007
    late = np.stack([np.interp(time - lag, time, torque[:, j]) for j in range(7)], axis=1)
    want = t.rows.link_at(late - torque)[train]
    timing = {"sensor_timing": np.array([lag])}
    got = (models.contributions({"payload": params, **timing}, train)[0]
           - models.contributions({"payload": params}, train)[0]
           - models.contributions(timing, train)[0])
    assert np.sqrt(np.mean(want**2)) > 1e-4  # N m: a change the channel can see
    assert np.sqrt(np.mean((got - want) ** 2)) < 0.05 * np.sqrt(np.mean(want**2))


def test_a_late_sensor_reads_the_nominal_torque_exactly_late() -> None:
    """The lag moves the windowed nominal link torque by its value ``lag`` earlier, not by
    minus lag x its rate: against the full-rate torque delayed by a cubic spline at every
    sample and windowed like the channel, within 1e-6 of the shift at 0.7, 1.6 and 3 ms, where
    the first-order shift misses 1.7-3.7 % of it on this twin (on a 12-hole cell's faster
    moves, 2 sigma left on the torque sensors of joints 2 and 4 at 1.6 ms)."""
    _, _, fam, train, _, _ = twin(None)
    t, models = fam.terms, fam._models
    torque = models.dyn.link_torque(t.q_full, t.dq_full, t.a_full)
    time = np.arange(len(torque)) / t.rate
    for lag in (0.0007, 0.0016, 0.003):
        want = t.rows.link_at(CubicSpline(time, torque, axis=0)(time - lag) - torque)[train]
        got = models.contributions({"sensor_timing": np.array([lag])}, train)[0]
        first_order = -link_rate(t, torque)[train] * lag
        size = np.sqrt(np.mean(want**2))
        assert size > 1e-3  # N m: a change the channel sees
        assert np.sqrt(np.mean((got - want) ** 2)) < 1e-6 * size
        assert np.sqrt(np.mean((first_order - want) ** 2)) > 0.01 * size  # a test that can fail


def test_family_implements_the_contract() -> None:
    _, _, fam, train, _, _ = twin(None)
    assert isinstance(fam, Family)
    # a coupled drive is a candidate only where the recording declares one (this twin does not)
    assert {e.name for e in fam.effects} == set(IN_LIBRARY) - set(DECLARED)
    params = {fam.baseline.name: fam.baseline.x0}
    r = fam.residual(params, train)
    assert r.shape == (len(train) * len(CHANNELS),) and np.all(np.isfinite(r))
    rows = fam.locate(train, r)
    assert {row.channel for row in rows} == set(CHANNELS)


def test_split_is_whole_time_blocks_that_share_no_sample() -> None:
    _, _, fam, train, held, _ = twin(None)
    t = fam.terms
    assert np.intersect1d(train, held).size == 0
    assert len(train) + len(held) == fam.n_samples
    block = np.floor((t.time - t.time[0]) / fam.cfg.block_s).astype(int)
    assert set(block[train] % 2).isdisjoint(block[held] % 2)  # alternate blocks, never mixed
    def samples(rows):
        return {int(s) for c in t.rows.centre[rows] for s in range(c - t.rows.half, c + t.rows.half + 1)}

    assert samples(train).isdisjoint(samples(held))  # the windows tile time


def test_effect_free_twin_sits_at_the_noise_floor_per_channel() -> None:
    """The row sigma is propagated from the recording's noise model (torque noise, encoder
    quantisation through the differentiation and the inertia); nothing is fitted to it."""
    _, _, fam, _, _, base = twin(None)
    rows = np.arange(fam.n_samples)
    w = fam.residual(base.params, rows).reshape(len(rows), len(CHANNELS))
    rms = np.sqrt(np.mean(w**2, axis=0))
    # 196 rows per channel: the RMS of unit noise scatters by 1/sqrt(2 * 196) = 5 %
    assert np.all((rms > 0.85) & (rms < 1.15)), dict(zip(CHANNELS, rms.round(3)))
    assert at_noise_floor(base, alpha=0.01), base.heldout_rms


def test_effect_free_twin_no_effect_earns_its_parameters() -> None:
    _, _, _, _, _, base = twin(None)
    for name, fit in single_fits(None).items():
        assert not earns(base, fit)[2], name


@pytest.mark.parametrize("effect", SINGLE)
def test_true_effect_gives_the_largest_heldout_gain(effect: str) -> None:
    _, _, _, _, _, base = twin(effect)
    gain = {name: base.heldout_chi2 - fit.heldout_chi2 for name, fit in single_fits(effect).items()}
    assert max(gain, key=gain.get) == effect, gain
    assert earns(base, single_fits(effect)[effect])[2]


@pytest.mark.parametrize("effect", SINGLE)
def test_fit_reaches_the_noise_floor_on_heldout_data(effect: str) -> None:
    _, _, _, _, _, base = twin(effect)
    fit = single_fits(effect)[effect]
    assert base.heldout_rms > 2.0  # the twin's effect is visible beyond noise
    assert fit.heldout_rms <= 1.5, fit.heldout_rms


_CHANCE_MISS = pytest.mark.xfail(strict=True, reason=(
    "seed 0: Fv1 is 3.01 sigma off (Fc1 2.6, Fc5 2.3). With 14 parameters a 3-sigma miss has "
    "~4 % probability by chance; over 4 seeds x 2 splits the RMS of the z-scores is 1.05"))


@pytest.mark.parametrize("effect", [pytest.param(e, marks=_CHANCE_MISS) if e == "joint_friction"
                                    else e for e in SINGLE])
def test_parameters_recovered_within_3_sigma(effect: str) -> None:
    """sigma: the fit's Jacobian covariance (Birge-scaled), engine-side."""
    _, answer, fam, _, _, _ = twin(effect)
    fit = single_fits(effect)[effect]
    block = next(e for e in fam.effects if e.name == effect)
    truth = np.array([answer["params"].get(n, 0.0) for n in block.param_names])
    # parameters the data cannot identify are held, not estimated (the twin conceals none)
    held = list(block.fixed)
    assert np.all(truth[held] == 0.0) and np.all(fit.params[effect][held] == 0.0)
    free = np.setdiff1d(np.arange(block.n_params), held)
    z = (fit.params[effect][free] - truth[free]) / fit.std[effect][free]
    assert np.all(np.abs(z) <= 3.0), dict(zip(np.array(block.param_names)[free], z.round(2)))


@pytest.mark.parametrize("effect", SINGLE)
def test_tares_recover_the_torque_sensor_offsets(effect: str) -> None:
    """The always-fitted baseline: start-up offsets, plus the torque_sensor twin's own."""
    _, answer, fam, _, _, _ = twin(effect)
    fit = single_fits(effect)[effect]
    z = (fit.params[fam.baseline.name] - np.asarray(answer["torque_offset"])) / fit.std[fam.baseline.name]
    assert np.all(np.abs(z) <= 3.0), z.round(2)


@pytest.mark.parametrize("effect", (None,) + SINGLE)
def test_forward_selection_names_the_effect(effect: str | None) -> None:
    _, _, fam, _, _, _ = twin(effect)
    result = diagnose(fam, seed=SEED)
    if effect is None:
        assert result.no_missing_physics, result.verdict
    else:
        assert result.top_effect == effect, [f.effect for f in result.findings]
        assert result.heldout_rms_after <= 1.5


@pytest.mark.parametrize("effect,blind", [("joint_friction", "tau_J"), ("latency", "tau_J"),
                                          ("torque_sensor", "tau_J_d")])
def test_locate_flags_only_the_channel_that_sees_the_effect(effect: str, blind: str) -> None:
    """Friction and latency act inside the drive (before the link-side sensor); a sensor gain
    acts on the sensor alone. The other channel must read as noise."""
    _, _, fam, _, _, base = twin(effect)
    rows = np.arange(fam.n_samples)
    table = fam.locate(rows, fam.residual(base.params, rows))
    flagged = {r.channel.rstrip("1234567") for r in table if r.flagged and r.group == "all"}
    assert flagged == {"tau_J", "tau_J_d"} - {blind}, flagged


def test_payload_regressor_matches_mujoco_with_the_body() -> None:
    """The payload's 10 standard-parameter columns, from 10 reference bodies, reproduce
    mj_rne of the arm carrying an arbitrary payload body."""
    _, _, fam, _, _, _ = twin(None)
    models: EffectModels = fam._models
    p = np.array([0.8, 0.02, -0.03, 0.06, 0.03, 0.01, 0.05, -0.02, 0.004, 0.04])  # extent
    dyn, body = payload_model()
    set_payload(dyn.model, body, payload_inertial(p))
    t = fam.terms
    rows = np.arange(0, fam.n_samples, 7)
    direct = t.rows.at(dyn.link_torque(t.q_full, t.dq_full, t.a_full))[rows]
    _, drive, _, _ = models.contributions({"payload": p}, rows)
    assert np.max(np.abs(drive - direct)) < 1e-9


def test_payload_inertia_is_fitted_physical() -> None:
    """The payload is fitted in its extent, so its inertia is a rigid body's by construction
    (not checked afterwards): positive definite with the principal moments' triangle
    inequalities, on any extent, and on the twin's fit the box's inertia is recovered."""
    rng = np.random.default_rng(0)
    for _ in range(200):
        extent = rng.uniform(-0.1, 0.1, 6)
        extent[[0, 2, 5]] = np.abs(extent[[0, 2, 5]]) + 1e-3
        assert inertia_problem(inertia_from_extent(rng.uniform(0.1, 5.0), extent)) == ""
    _, answer, _, _, _, _ = twin("payload")
    p = single_fits("payload")["payload"].params["payload"]
    inertia = payload_inertial(p)[4:]
    assert inertia_problem(tuple(inertia)) == ""
    truth = [answer["params"][n] for n in ("Ixx", "Iyy", "Izz")]
    np.testing.assert_allclose(inertia[:3], truth, rtol=0.5)


def test_twin_answer_stays_out_of_the_recording() -> None:
    rec, answer, _, _, _, _ = twin("payload")
    text = json.dumps(rec.meta.as_json())
    assert "payload" not in text and "mass" not in text
    assert answer["effect"] == "payload" and answer["saturated_samples"] == 0
    assert rec.signals.num_rows == int(DURATION * rec.meta.sample_rate_hz)


def test_twin_rejects_unknown_effect_and_bad_magnitude() -> None:
    with pytest.raises(ConfigError, match="unknown effect 'backlash'; valid: joint_friction"):
        make_twin("backlash", None, 0)
    with pytest.raises(ConfigError, match="magnitude -1"):
        make_twin("payload", -1.0, 0)


# -- bad input ---------------------------------------------------------------------------

def _edited(change) -> Recording:
    rec = twin(None)[0]
    cols = {c: rec.signals.column(c) for c in rec.signals.column_names}
    if isinstance(change, str):  # "drop NAME": the channel and its noise sigma
        name = change.split()[1]
        cols.pop(name)
        sigma = {k: v for k, v in rec.meta.noise_sigma.items() if k != name}
        return Recording(dataclasses.replace(rec.meta, channels=tuple(cols), noise_sigma=sigma),
                         pa.table(cols))
    change(cols)
    return Recording(dataclasses.replace(rec.meta, channels=tuple(cols)), pa.table(cols))


def _set(name: str, fn):
    def change(cols):
        cols[name] = pa.array(fn(cols[name].to_numpy().copy()))
    return change


@pytest.mark.parametrize("change,message", [
    ("drop tau_J3", r"the recording has tau_J1, .* but not tau_J3: give tau_J of all 7 joints"),
    ("drop q5", r"needs channels q5, not in the recording"),
    ("drop tau_J_d5", r"the recording has tau_J_d1, .* but not tau_J_d5: give tau_J_d of all 7"),
    (_set("q4", lambda x: np.r_[x[:-10], [None] * 10]), r"channel q4 has 10 missing sample\(s\)"),
    (_set("tau_J_d2", lambda x: np.where(np.arange(len(x)) == 500, np.nan, x)),
     r"channel tau_J_d2 has 1 non-finite sample\(s\) \(NaN/inf\), first at row 500"),
    (_set("time", lambda x: np.r_[x[:300], x[299], x[301:]]), r"time must increase strictly \(row 300"),
    (_set("time", lambda x: x * np.where(np.arange(len(x)) > 1000, 1.5, 1.0)),
     r"samples are not uniform at 1000 Hz .*`serpar import FILE --rate 1000`"),
    (_set("q2", lambda x: np.degrees(x)), r"q2 reaches .* outside the Panda's range .* degrees"),
    (_set("tau_J4", lambda x: 1000.0 * x), r"tau_J4 varies 1e\+03 times as much as the nominal"),
    (_set("tau_J_d2", lambda x: -x), r"tau_J_d2 varies -1 times as much .* another robot"),
])
def test_bad_input_is_one_line_naming_the_problem(change, message: str) -> None:
    with pytest.raises(IdentificationError, match=message) as err:
        family_from_recording(_edited(change))
    assert "\n" not in str(err.value)


def test_a_torque_sensor_stated_noiseless_is_refused() -> None:
    """A stated sigma of 0 (an ideal sensor) cannot whiten the torque misfit: one line naming
    the channel, not a singular fit."""
    rec = twin(None)[0]
    sigma = {**rec.meta.noise_sigma, "tau_J3": 0.0}
    bad = Recording(dataclasses.replace(rec.meta, noise_sigma=sigma), rec.signals)
    with pytest.raises(IdentificationError, match=r"noise_sigma of tau_J3 is 0: .*> 0\)$"):
        family_from_recording(bad)


def _measured_torque_only(effect: str) -> Recording:
    rec = twin(effect)[0]
    keep = [c for c in rec.signals.column_names if not c.startswith("tau_J_d")]
    sigma = {k: v for k, v in rec.meta.noise_sigma.items() if k in keep}
    return Recording(dataclasses.replace(rec.meta, channels=tuple(keep), noise_sigma=sigma),
                     rec.signals.select(keep))


def test_a_log_of_measured_torque_only_is_diagnosed() -> None:
    """No tau_J_d (a published log of q and tau_J): the torque sensors' channel alone. A
    payload shows there and is found; friction inside the drive acts before the torque sensor,
    so a joint-friction twin's log shows nothing beyond noise, and the notes say why."""
    fam = family_from_recording(_measured_torque_only("payload"))
    assert fam.channels == ch.TAU_J and "joint_friction" not in {e.name for e in fam.effects}
    d = diagnose(fam, seed=SEED)
    assert [f.effect for f in d.established] == ["payload"] and d.heldout_rms_after <= 1.5
    mass = next(p for p in d.findings[0].params if p.name == "mass")
    assert abs(mass.value - twin("payload")[1]["params"]["mass"]) < 3 * mass.std + 1e-3
    fam = family_from_recording(_measured_torque_only("joint_friction"))
    d = diagnose(fam, seed=SEED)
    assert d.established == () and "not candidates" in fam.notes[0]


def test_too_short_a_recording_is_refused() -> None:
    short = _edited(lambda cols: None)
    short = Recording(short.meta, short.signals.slice(0, 1500))
    with pytest.raises(IdentificationError, match="windows of 51"):
        family_from_recording(short)


def test_stribeck_friction_is_found_as_its_coulomb_level_and_its_fall() -> None:
    """The twin's drives lose Fc + (Fs - Fc) exp(-(v/vs)^2) + Fv v with vs 0.02-0.08 rad/s per
    joint: joint friction, then the Stribeck fall with each joint's own transition speed, both
    established and nothing else; the held-out residual at the noise; of the 28 parameters
    (Fc, Fv, dFs = Fs - Fc, vs per joint) >= 90 % within 2 sigma of the truth, none beyond 4.
    Measured (seed 0, 10 s): RMS 1.03 x sigma; one vs shared by the seven drives left 1.8 x."""
    _, answer, fam, _, _, _ = twin("stribeck_friction")
    result = diagnose(fam, seed=SEED)
    assert [f.effect for f in result.established] == ["joint_friction", "stribeck_friction"], \
        result.verdict
    assert result.heldout_rms_after < 0.05 * result.heldout_rms_before
    assert result.residual.passes, result.verdict
    truth = answer["params"]
    z = np.array([(p.value - truth[p.name]) / p.std for f in result.established
                  for p in f.params])
    assert z.size == 28 and np.mean(np.abs(z) <= 2.0) >= 0.9 and np.all(np.abs(z) <= 4.0), z


# -- a state restore (an episode's broken hole cycle) ------------------------------------

def _restored(rec: Recording, at: int, back: int) -> Recording:
    """``rec`` with its state put back ``back`` samples at row ``at``, the way the episode
    recorder writes a restore: the period spanning it left out, ``time`` going on."""
    n = rec.signals.num_rows
    idx = np.r_[np.arange(at), np.arange(at - back, n)]
    cols = {c: pa.array(rec.signals.column(c).to_numpy()[idx]) for c in rec.signals.column_names}
    t = rec.signals.column("time").to_numpy()
    dt = t[1] - t[0]
    cols["time"] = pa.array(t[0] + dt * np.r_[np.arange(at), at + 1 + np.arange(n - at + back)])
    return Recording(rec.meta, pa.table(cols))


def test_a_restore_starts_a_new_stretch_no_window_reaches_across() -> None:
    """Allowed (an episode), a gap of whole periods is a break: every comparison window lies in
    one stretch, and the twin's friction is named as on the unbroken recording. The state jumps
    0.5 s back at the break, so a window across it would read a huge acceleration."""
    at = 4000
    broken = _restored(twin("joint_friction")[0], at, 500)
    with pytest.raises(IdentificationError, match=r"not uniform at 1000 Hz \(interval 0.002 s"):
        family_from_recording(broken)
    fam = family_from_recording(broken, breaks_allowed=True)
    rows = fam.terms.rows
    lo, hi = rows.centre - rows.half - 2, rows.centre + rows.half + 2
    assert not np.any((lo < at) & (hi >= at))
    assert np.min(rows.centre[rows.centre > at]) - rows.half - at >= 30  # the latency's look back
    result = diagnose(fam, seed=SEED)
    assert result.top_effect == "joint_friction" and result.heldout_rms_after <= 1.5, result.verdict


def test_a_gap_of_part_of_a_period_is_refused_even_where_breaks_are_allowed() -> None:
    rec = twin(None)[0]
    t = rec.signals.column("time").to_numpy().copy()
    t[3000:] += 0.5 * (t[1] - t[0])
    cols = {c: rec.signals.column(c) for c in rec.signals.column_names}
    cols["time"] = pa.array(t)
    with pytest.raises(IdentificationError, match=r"not uniform at 1000 Hz \(interval 0.0015 s at row 3000"):
        family_from_recording(Recording(rec.meta, pa.table(cols)), breaks_allowed=True)
