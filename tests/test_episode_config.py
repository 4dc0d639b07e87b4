"""The episode config (validated, YAML with unknown keys rejected), the hidden Stewart errors
and the success-rate interval."""

from __future__ import annotations

import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim.config_io import load_yaml_config
from serpar.tasks.episode_config import (
    EpisodeConfig,
    HiddenStewartErrors,
    Outcome,
    table5_errors,
    wilson_interval,
)


def test_yaml_round_trip_and_unknown_keys(tmp_path):
    good = tmp_path / "e.yaml"
    good.write_text("seed: 3\nholes: [0, 5, 7]\ncontroller: impedance\nhidden_errors: {mode: random, scale: 2}\n")
    cfg = load_yaml_config(EpisodeConfig, good)
    assert cfg.holes == (0, 5, 7) and cfg.controller == "impedance" and cfg.hidden_errors.scale == 2
    bad = tmp_path / "b.yaml"
    bad.write_text("seed: 3\ncontroler: impedance\n")
    with pytest.raises(ConfigError, match="unknown key\\(s\\) controler; valid: seed, holes, controller"):
        load_yaml_config(EpisodeConfig, bad)


@pytest.mark.parametrize("kwargs, needle", [
    ({"controller": "pid"}, "valid: force_position, impedance"),
    ({"holes": 40}, "a count in 1..36"),
    ({"holes": (1, 1)}, "distinct indices"),
    ({"camera_width": 640}, "valid: 2048, 1024"),
    ({"stewart_correction": False, "stewart_calibration": "p.json"}, "would be unused"),
    ({"stewart_calibration": ""}, "valid: campaign, none or the path of a parameters file"),
    ({"stewart_calibration": None}, "valid: campaign, none or the path of a parameters file"),
])
def test_bad_config_names_the_valid_choices(kwargs, needle):
    with pytest.raises(ConfigError, match=needle):
        EpisodeConfig(**kwargs)


def test_bad_hidden_error_mode():
    with pytest.raises(ConfigError, match="valid: table5, random, none"):
        HiddenStewartErrors(mode="big")


def test_hidden_errors_follow_table5():
    table = table5_errors()
    assert table.shape == (6, 7)
    assert table[2, 6] == pytest.approx(0.8039e-3)  # leg 3, dBz: the largest entry of Table 5
    assert np.array_equal(HiddenStewartErrors().draw(0), table)
    assert not HiddenStewartErrors(mode="none").draw(0).any()
    drawn = np.array([HiddenStewartErrors(mode="random").draw(s) for s in range(400)])
    rms_drawn = np.sqrt(np.mean(drawn**2, axis=(0, 1)))
    assert rms_drawn == pytest.approx(np.sqrt(np.mean(table**2, axis=0)), rel=0.1)


def test_wilson_interval_known_values():
    lo, hi = wilson_interval(36, 36)
    assert lo == pytest.approx(0.9036, abs=1e-3) and hi == 1.0
    lo, hi = wilson_interval(0, 10)
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-3)
    lo, hi = wilson_interval(50, 100)
    assert lo == pytest.approx(0.4038, abs=1e-3) and hi == pytest.approx(0.5962, abs=1e-3)
    with pytest.raises(ConfigError):
        wilson_interval(3, 2)


def test_outcomes_are_the_issue_taxonomy():
    """The episode's outcomes, and sim_fault: a Monte Carlo trial the simulator could not finish."""
    assert [o.value for o in Outcome] == ["success", "vision_miss", "grasp_fail", "align_fail", "jam",
                                          "overforce", "timeout", "dropped", "sim_fault"]
