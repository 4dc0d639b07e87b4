"""Diagnosis of an assembly episode (issue 7): a recorded one-hole episode of the full cell,
diagnosed blind from its arm signals. The cell's arm has the Panda's dry joint friction
(``EpisodeConfig.arm_friction`` x Gaz et al.'s levels, MuJoCo frictionloss) that the
controllers' model leaves out; the diagnosis must name it and recover it from the free-motion
phases, with the contact phases (grasp, insert, release) excluded and counted."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from diagnosis_support import RMS_TARGET

from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.config_model import model_from_episode_config
from serpar.diagnosis.episode_family import EpisodeFamily, free_windows
from serpar.diagnosis.insertion_friction import NOMINAL_MU
from serpar.diagnosis.prior import PriorFamily
from serpar.diagnosis.select import diagnose
from serpar.errors import ConfigError
from serpar.sim.arm import GAZ_FRICTION_PHI, PANDA_COULOMB_FRICTION
from serpar.sim.recording import read_recording
from serpar.tasks.episode import run_episode
from serpar.tasks.episode_config import EpisodeConfig

pytestmark = [pytest.mark.xdist_group("calibrated"), pytest.mark.slow]

EPISODES = {"friction": ((14,), 0.3, None), "none": ((14,), 0.0, None),
            "contact": ((14, 15, 20, 21), 0.3, 0.5)}
"""Episode -> (holes, the arm's dry friction as a share of the Panda's (0.3: the default cell),
journal/bore friction (None: the nominal 0.2))."""
CONTACT_MU = 0.5


@pytest.fixture(scope="module")
def episodes(calibrated_top, calibrated_inspect, tmp_path_factory):
    pairs = {"top": calibrated_top.calibration.pair, "inspect": calibrated_inspect.calibration.pair}
    out = {}
    for name, (holes, scale, mu) in EPISODES.items():
        folder = tmp_path_factory.mktemp(name) / "episode"
        cfg = EpisodeConfig(holes=holes, stewart_calibration="none", arm_friction=scale,
                            contact_friction=mu)
        summary = run_episode(cfg, pairs, recording=folder)
        # at journal/bore friction 0.5 a journal may jam (overforce): physics, not a failure
        assert summary.successes >= (len(holes) if mu is None else 2), summary
        rec = read_recording(folder)
        # the truth stays out of what the diagnosis reads
        model = {k: v for k, v in rec.meta.model.items() if k != "episode_config"}
        rec = dataclasses.replace(rec, meta=dataclasses.replace(rec.meta, model=model))
        family = family_from_recording(rec)
        out[name] = (rec, family, diagnose(family, 0))
    return out


def test_an_episode_recording_is_diagnosed_by_the_episode_family(episodes) -> None:
    for _, family, _ in episodes.values():
        assert isinstance(family, EpisodeFamily)


def test_contact_phases_are_excluded_and_counted(episodes) -> None:
    rec, family, _ = episodes["friction"]
    keep, excluded = free_windows(rec, family.inner)
    assert len(keep) + sum(excluded.values()) == family.inner.n_samples  # nothing dropped silently
    assert family.n_samples == len(keep)  # under two chamfer slides: contact friction not a candidate
    assert "contact_friction" not in {e.name for e in family.effects}
    # and the diagnosis says so, with why
    (why,) = episodes["friction"][2].not_identifiable
    assert re.match(r"contact_friction \([01] chamfer slides? in these insertions, 2 needed", why), why
    assert excluded["grasp"] > 20 and excluded["insert"] > 10 and excluded["release"] > 0
    assert "insert" in family.kind and "grasp" in family.kind
    phase_rows = {r.label for r in family.locate(np.arange(family.n_samples),
                                                 np.zeros(family.n_samples * 14))
                  if r.group == "phase"}
    assert not phase_rows & {"grasp", "insert", "release"}


def test_unmodelled_joint_friction_is_named_and_recovered(episodes) -> None:
    _, _, diag = episodes["friction"]
    assert diag.top_effect == "joint_friction", diag.verdict
    finding = next(f for f in diag.findings if f.effect == "joint_friction")
    fitted = {p.name: p.value for p in finding.params}
    truth = 0.3 * np.array(PANDA_COULOMB_FRICTION)
    got = np.array([fitted[f"Fc{j}"] for j in range(1, 8)])
    assert np.all(np.abs(got - truth) <= 0.05 * truth), (got, truth)
    assert diag.heldout_rms_before > 10.0  # the friction dominates the nominal residual


def test_heldout_rms_after_the_fit_near_noise_floor(episodes) -> None:
    _, _, diag = episodes["friction"]
    assert diag.heldout_rms_after <= RMS_TARGET


def test_frictionless_episode_says_no_missing_physics(episodes) -> None:
    """The cell samples like the real arm (controllers/arm_sensors.py TorqueADC, the command
    switch centred on the period start) and logs the load it carries (m_load, F_x_Cload), so
    an effect-free episode leaves nothing for the diagnosis: no latency or sensor timing."""
    _, _, diag = episodes["none"]
    assert diag.no_missing_physics, diag.verdict
    assert not diag.findings, diag.verdict


def test_the_carried_part_is_declared_as_the_load(episodes) -> None:
    """m_load is the conductor's nominal mass from grasp to release and 0 otherwise; without
    it the part's weight (1.7 g at ~0.6 m: ~0.01 N m on joint 2) is structure in the residual."""
    rec, _, diag = episodes["none"]
    m_load = rec.column("m_load")
    phase = np.array(rec.signals.column("phase").to_pylist())
    held = np.isin(phase, ("inspect", "align", "insert"))
    empty = np.isin(phase, ("start", "register", "locate"))
    mass = np.unique(m_load[held])
    assert mass.size == 1 and 1.5e-3 < mass[0] < 2.0e-3, mass  # 5 mm x 10 mm brass + journal
    assert np.all(m_load[empty] == 0.0)
    assert 0.09 < float(np.median(rec.column("F_x_Cload3")[held])) < 0.11  # at the pads, past the flange
    drop = ["m_load", "F_x_Cload1", "F_x_Cload2", "F_x_Cload3"]
    meta = dataclasses.replace(rec.meta, channels=tuple(c for c in rec.meta.channels if c not in drop))
    unaware = diagnose(family_from_recording(dataclasses.replace(
        rec, meta=meta, signals=rec.signals.drop_columns(drop))), 0)
    assert unaware.heldout_rms_before > diag.heldout_rms_before + 0.05, (
        unaware.heldout_rms_before, diag.heldout_rms_before)


def test_frictionless_episode_does_not_find_joint_friction(episodes) -> None:
    _, _, diag = episodes["none"]
    assert "joint_friction" not in {f.effect for f in diag.findings}, diag.verdict


def test_against_the_cell_config_the_friction_is_no_longer_missing(episodes, tmp_path) -> None:
    """``serpar diagnose REC --model cell.yaml``: the cell the config builds (its arm friction)
    is the nominal model, so what was the top finding is explained before any fit."""
    _, family, blind = episodes["friction"]
    cell = tmp_path / "cell.yaml"
    cell.write_text("holes: [14]\narm_friction: 0.3\n")
    diag = diagnose(PriorFamily(family, model_from_episode_config(cell)), 0)
    assert "joint_friction" not in {f.effect for f in diag.findings}, diag.verdict
    assert diag.heldout_rms_before < 0.15 * blind.heldout_rms_before


def test_against_a_model_the_episode_keeps_its_folds_and_noise_estimate(episodes, tmp_path
                                                                        ) -> None:
    """A prior changes the nominal prediction, not how the recording is resampled or its noise
    estimated: the chamfer slides are dealt to every fold as the episode deals them (without
    the episode's folds they would sit in one contiguous fold) and the residual check can
    tell noise from structure."""
    _, family, _ = episodes["contact"]
    cell = tmp_path / "cell.yaml"
    cell.write_text("arm_friction: 0.3\n")
    prior = PriorFamily(family, model_from_episode_config(cell))
    for (a, b), (c, d) in zip(prior.folds(5), family.folds(5), strict=True):
        np.testing.assert_array_equal(a, c)
        np.testing.assert_array_equal(b, d)
    slides = family.n_arm + np.arange(family.slides.n)
    assert all(np.isin(slides, held).any() for _, held in prior.folds(min(5, family.slides.n)))
    rows = np.arange(family.n_samples)
    white = np.random.default_rng(0).normal(size=14 * family.n_arm + family.slides.n)
    ratio, _ = prior.noise_ratio(rows, white)
    assert 0.9 < ratio < 1.1


def test_episode_config_as_a_model(tmp_path) -> None:
    cell = tmp_path / "cell.yaml"
    cell.write_text("arm_friction: 0.5\n")
    model = model_from_episode_config(cell)
    assert model.effects == ("joint_friction",)
    block = model.block("joint_friction")
    assert np.allclose(block.values[:7], 0.5 * np.array(PANDA_COULOMB_FRICTION))
    assert np.allclose(block.values[7:], 0.0)
    cell.write_text("arm_friction: 0.0\n")
    assert model_from_episode_config(cell).effects == ()
    # the published form: the cell's drive torque exactly, in sigmoid_friction's names
    cell.write_text("arm_friction: 2.5\narm_friction_form: gaz\n")
    model = model_from_episode_config(cell)
    assert model.effects == ("sigmoid_friction",)
    phi = model.block("sigmoid_friction").as_dict()
    assert phi["phi1_4"] == 2.5 * GAZ_FRICTION_PHI[0][3] and phi["phi2_6"] == GAZ_FRICTION_PHI[1][5]
    assert phi["phi3_3"] == GAZ_FRICTION_PHI[2][2]
    with pytest.raises(ConfigError, match="not found"):
        model_from_episode_config(tmp_path / "missing.yaml")
    cell.write_text("arm_frictoin: 0.3\n")
    with pytest.raises(ConfigError, match="arm_frictoin"):
        model_from_episode_config(cell)


def test_higher_contact_friction_is_found_in_the_chamfer_slides(episodes) -> None:
    """Journal/bore friction 0.5 against the nominal 0.2: the wrench estimate's lateral/axial
    ratio on the chamfer, (1 - mu)/(1 + mu), gives it away on the held-out insertion."""
    _, family, diag = episodes["contact"]
    assert family.slides is not None and family.slides.n >= 2
    assert diag.top_effect == "joint_friction", diag.verdict  # the arm's, as ever
    ratio = family.slides.lateral / family.slides.axial
    found = [f for f in diag.findings if f.effect == "contact_friction"]
    assert found, (diag.verdict, "slide mu", (1 - ratio) / (1 + ratio))
    finding = found[0]
    # established: judged on the slides, not on the arm rows under their noise floor
    assert finding.established, finding.reasons
    (d_mu,) = finding.params
    mu = NOMINAL_MU + d_mu.value
    assert abs(mu - CONTACT_MU) <= 3 * d_mu.std, (mu, d_mu.std)
    assert mu > NOMINAL_MU + 0.1


def test_an_episode_without_the_wrench_estimate_still_diagnoses_the_arm(episodes) -> None:
    """A recording without O_F_ext_hat_K / O_T_EE_z: no chamfer rows, and the report says why."""
    rec, _, _ = episodes["friction"]
    drop = [c for c in rec.signals.column_names if c.startswith(("O_F_ext_hat_K", "O_T_EE"))]
    meta = dataclasses.replace(rec.meta, channels=tuple(c for c in rec.meta.channels
                                                        if c not in drop))
    bare = dataclasses.replace(rec, meta=meta, signals=rec.signals.drop_columns(drop))
    family = family_from_recording(bare)
    assert family.slides is None and "no O_T_EE_z" in family.kind
    assert "contact_friction" not in {e.name for e in family.effects}
    # and the diagnosis says so, with why
    (why,) = episodes["friction"][2].not_identifiable
    assert re.match(r"contact_friction \([01] chamfer slides? in these insertions, 2 needed", why), why


def _without_the_command(rec):
    drop = [c for c in rec.signals.column_names if c.startswith("tau_J_d")]
    meta = dataclasses.replace(rec.meta, channels=tuple(c for c in rec.meta.channels if c not in drop),
                               noise_sigma={k: v for k, v in rec.meta.noise_sigma.items() if k not in drop})
    return dataclasses.replace(rec, meta=meta, signals=rec.signals.drop_columns(drop))


def test_an_episode_without_the_commanded_torque_is_diagnosed_on_the_sensors(episodes) -> None:
    """A recording without tau_J_d (a robot that logs no command): seven channels per arm row,
    not fourteen, through the split, the fit and the noise test (this raised a reshape error);
    the frictionless episode then establishes nothing on its torque sensors either."""
    family = family_from_recording(_without_the_command(episodes["none"][0]))
    assert len(family.inner.channels) == 7
    d = diagnose(family, 0)
    assert not [f for f in d.findings if f.established], d.verdict


@pytest.mark.xfail(strict=True, reason="the torque sensors alone keep structure the nominal "
                   "model does not explain: held-out RMS 1.22 x sigma (p 4e-12) on the "
                   "frictionless episode, data noise 1.02 x; not found yet")
def test_on_the_sensors_alone_the_frictionless_episode_leaves_noise(episodes) -> None:
    d = diagnose(family_from_recording(_without_the_command(episodes["none"][0])), 0)
    assert d.residual.passes, d.verdict
