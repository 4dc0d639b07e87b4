"""Stewart twins that the blind bench also draws with their candidate withheld from the
diagnosis library (twins/stewart_twin.py WITHHELD): the physics each puts into the "real" platform, read back from the plant and
from the recording the way a metrologist would (motion capture through the nominal inverse
kinematics against the leg encoders), and the validation of the plant's new Reality fields."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import inverse_kinematics
from serpar.sim import channels as ch
from serpar.sim.plants.stewart_platform import PlatformPlant, Reality
from serpar.sim.stewart import StewartConfig
from serpar.twins.stewart_twin import (
    DEFAULT_MAGNITUDE,
    EFFECTS,
    MAGNITUDE_RANGE,
    OUT_OF_LIBRARY,
    STEEL_PER_K,
    UNITS,
    WITHHELD,
    make_twin,
)

HOLD = 100
"""Samples per 1 s rest hold at 100 Hz."""


def _holds(rec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per hold: time [s], true-stroke estimate from motion capture through the nominal
    inverse kinematics (n, 6) [m], and the leg encoders' stroke reading (n, 6) [m]."""
    cfg = StewartConfig()
    sig = rec.signals

    def mean(names: tuple[str, ...]) -> np.ndarray:
        cols = np.column_stack([np.asarray(sig[c]) for c in names])
        return cols.reshape(-1, HOLD, len(names)).mean(axis=1)

    q = mean(ch.PLATFORM_QUAT)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rot = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()
    mocap_stroke = inverse_kinematics(cfg.geometry(), mean(ch.PLATFORM_POSITION), rot)
    return mean((ch.TIME,))[:, 0], mocap_stroke, mean(ch.LEG) - cfg.l_min


def test_out_of_library_effects_are_registered() -> None:
    assert OUT_OF_LIBRARY == () and WITHHELD == ("leg_thermal_nonuniform", "leg_encoder_scale")
    for effect in WITHHELD:
        assert effect in EFFECTS and effect in UNITS and effect in DEFAULT_MAGNITUDE
        lo, hi = MAGNITUDE_RANGE[effect]
        assert 0 < lo < DEFAULT_MAGNITUDE[effect] < hi


@pytest.mark.parametrize("effect", OUT_OF_LIBRARY + WITHHELD)
def test_answer_carries_a_signature_and_stays_out_of_the_recording(effect: str) -> None:
    rec, answer = make_twin(effect, None, 1, n_poses=30)
    sig = answer["signature"]
    assert set(sig) == {"channels", "variables", "words"} and sig["words"]
    assert all(c in {f"leg {i}" for i in range(1, 7)} for c in sig["channels"])
    if effect == "leg_thermal_nonuniform":
        assert sig["channels"] == [f"leg {i}" for i in answer["params"]["legs"]]
        assert sig["variables"] == ["time"]
    else:
        leg = answer["params"]["leg"]
        assert sig["channels"] == [f"leg {leg}"] and sig["variables"] == [f"stroke {leg}"]
    json.dumps(answer)  # the bench writes answers as JSON
    assert effect not in json.dumps(rec.meta.model) and "signature" not in json.dumps(rec.meta.model)


def test_in_library_answers_carry_no_signature() -> None:
    assert "signature" not in make_twin("leg_encoder_offset", None, 0, n_poses=20)[1]


def test_warmed_legs_grow_alone_and_saturate_at_the_plant() -> None:
    sat = np.array([0.0, 4e-4, 0.0, 0.0, 2e-4, 0.0])  # legs 2 and 5: 35 K and 17 K of steel
    tau = np.full(6, 200.0)
    plant = PlatformPlant(Reality(growth_saturation=sat, growth_tau_s=tau))
    cfg = StewartConfig()
    geom = cfg.geometry()
    pos, rot = np.asarray(geom.home_pos, float), np.eye(3)
    strokes = inverse_kinematics(geom, pos, rot)

    def growth(t: float) -> np.ndarray:
        p, r, slides, _ = plant.settle(strokes, t, (pos, rot))
        true_len = np.linalg.norm(p + plant.P @ r.T - plant.B, axis=1)
        return true_len - (plant.L0 + slides)  # joint-to-joint length beyond the slide's

    full = sat * (plant.L0 + strokes)
    assert np.all(np.abs(growth(0.0)) < 0.5e-6)
    assert np.allclose(growth(200.0), full * (1 - np.exp(-1)), rtol=0.05, atol=0.5e-6)
    late = growth(3000.0)  # 15 time constants: saturated
    assert np.allclose(late[[1, 4]], full[[1, 4]], rtol=0.1)
    assert np.all(np.abs(late[[0, 2, 3, 5]]) < 0.5e-6)


def test_thermal_twin_pose_error_grows_on_two_legs_and_saturates() -> None:
    rec, answer = make_twin("leg_thermal_nonuniform", 40.0, 2)
    p = answer["params"]
    legs = np.asarray(p["legs"]) - 1
    assert p["dT_max_k"][0] == 40.0 or p["dT_max_k"][1] == 40.0
    assert all(20.0 <= d <= 40.0 for d in p["dT_max_k"]) and all(120 <= t <= 360 for t in p["tau_s"])
    t, mocap, enc = _holds(rec)
    excess = mocap - enc  # how far each leg really stands out beyond what its encoder says
    cold = np.setdiff1d(np.arange(6), legs)
    assert np.all(np.abs(excess[:, cold].mean(axis=0)) < 3e-6)
    length = StewartConfig().l_min + enc
    for j, leg in enumerate(legs):
        full = STEEL_PER_K * p["dT_max_k"][j] * length[:, leg]
        expected = full * -np.expm1(-t / p["tau_s"][j])
        assert np.sqrt(np.mean((excess[:, leg] - expected) ** 2)) < 10e-6  # ~6 um: the hold's mocap noise
        assert excess[:5, leg].mean() < 0.2 * full.mean()  # cold at the start
        late = slice(-10, None)  # this seed's legs are > 3 time constants warm by then
        assert t[late].min() > 3 * p["tau_s"][j]
        assert excess[late, leg].mean() == pytest.approx(full[late].mean(), rel=0.1)
        # saturates: the last third adds far less than the first (linear drift: as much)
        third = len(t) // 3
        first = excess[third, leg] - excess[0, leg]
        assert abs(excess[-third:, leg].mean() - excess[-2 * third:-third, leg].mean()) < 0.3 * first


def test_encoder_scale_twin_reads_off_in_proportion_to_stroke_on_one_leg() -> None:
    rec, answer = make_twin("leg_encoder_scale", 3e-3, 4)
    leg, scale = answer["params"]["leg"] - 1, answer["params"]["scale"]
    assert abs(scale) == 3e-3
    _, mocap, enc = _holds(rec)
    for i in range(6):
        slope, intercept = np.polyfit(mocap[:, i], enc[:, i] - mocap[:, i], 1)
        if i == leg:
            assert slope == pytest.approx(scale, rel=0.1)
            assert abs(intercept) < 10e-6  # zero at the encoder zero: no offset
        else:
            assert abs(slope) < 0.1 * abs(scale) and abs(intercept) < 10e-6, i


def test_servo_holds_the_scaled_encoder_at_the_command() -> None:
    reality = Reality(encoder_scale=np.array([0.0, 0.0, 2e-3, 0.0, 0.0, 0.0]),
                      encoder_offset_m=np.full(6, 1e-5))
    cmd = np.full(6, 0.025)
    stroke = reality.stroke_for_reading(cmd)
    assert np.allclose(stroke * (1 + reality.encoder_scale) + reality.encoder_offset_m, cmd)
    assert np.allclose(np.delete(stroke, 2), 0.025 - 1e-5)


def test_uniform_drift_alone_stays_linear_and_uniform() -> None:
    reality = Reality(growth_per_s=1e-8)
    assert reality.relative_growth(100.0) == 1e-8 * 100.0


@pytest.mark.parametrize("kwargs, message", [
    ({"encoder_scale": np.zeros(5)}, "encoder_scale must be 6 values in"),
    ({"encoder_scale": np.full(6, 0.2)}, r"\[-0.05, 0.05\]"),
    ({"encoder_scale": np.full(6, np.nan)}, "encoder_scale"),
    ({"growth_saturation": np.zeros(6)}, "both or neither"),
    ({"growth_tau_s": np.ones(6)}, "both or neither"),
    ({"growth_saturation": np.zeros(4), "growth_tau_s": np.ones(6)}, "growth_saturation must be 6"),
    ({"growth_saturation": np.full(6, 0.5), "growth_tau_s": np.ones(6)}, r"\[-0.01, 0.01\]"),
    ({"growth_saturation": np.zeros(6), "growth_tau_s": np.zeros(6)}, "finite values > 0"),
    ({"growth_saturation": np.zeros(6), "growth_tau_s": np.full(6, np.inf)}, "growth_tau_s"),
    ({"growth_per_s": float("nan")}, "growth_per_s"),
])
def test_invalid_reality_is_refused_naming_the_valid_range(kwargs, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        Reality(**kwargs)


@pytest.mark.parametrize("effect", OUT_OF_LIBRARY + WITHHELD)
def test_bad_magnitude_names_the_range(effect: str) -> None:
    with pytest.raises(ConfigError, match="blind-bench range"):
        make_twin(effect, -1.0, 0)
