"""Which platform model step 5 uses: nominal, a parameters file, or the in-cell campaign's
result, computed once and then read from the cache."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from serpar.calibration.stewart_params import save_stewart_parameters
from serpar.errors import ConfigError
from serpar.tasks import platform_model as stewart_model
from serpar.tasks.episode_config import EpisodeConfig, HiddenStewartErrors
from serpar.tasks.platform_model import believed_errors, prepare_models

IDENTIFIED = np.full((6, 7), 1e-5)


@pytest.fixture
def counted_campaign(monkeypatch, tmp_path):
    """The campaign replaced by a counter (the real one is test_ablation's and
    test_stewart_identification's), the cache in a fresh folder."""
    monkeypatch.setenv("SERPAR_CACHE", str(tmp_path))
    calls = []

    def campaign(scene_cfg, n_poses, noise, seed):
        calls.append(seed)
        return SimpleNamespace(errors=IDENTIFIED, residual_rms_m=1e-6)

    monkeypatch.setattr(stewart_model, "calibrate", campaign)
    return calls


def test_nominal_and_serial_alone_use_no_parameters(counted_campaign):
    assert believed_errors(EpisodeConfig(stewart_calibration="none")) is None
    assert believed_errors(EpisodeConfig(stewart_correction=False)) is None
    assert counted_campaign == []


def test_the_campaign_runs_once_per_platform_then_comes_from_the_cache(counted_campaign):
    logged = []
    prepare_models([EpisodeConfig(seed=s) for s in range(3)], logged.append)
    np.testing.assert_array_equal(believed_errors(EpisodeConfig(seed=5)), IDENTIFIED)
    assert counted_campaign == [0]  # Table 5 errors: one platform for every seed
    assert len(logged) == 1 and "calibrating the Stewart platform" in logged[0]
    random = HiddenStewartErrors(mode="random")
    prepare_models([EpisodeConfig(seed=0, hidden_errors=random), EpisodeConfig(seed=1, hidden_errors=random)])
    assert counted_campaign == [0, 0, 1]  # per-seed hidden errors: a campaign for each platform


def test_a_parameters_file_is_read_and_a_bad_one_fails(counted_campaign, tmp_path):
    path = save_stewart_parameters(tmp_path / "p.json", 2 * IDENTIFIED)
    np.testing.assert_array_equal(believed_errors(EpisodeConfig(stewart_calibration=str(path))), 2 * IDENTIFIED)
    with pytest.raises(ConfigError, match="cannot read"):
        prepare_models([EpisodeConfig(stewart_calibration=str(tmp_path / "missing.json"))])
    assert counted_campaign == []
    assert not list(tmp_path.glob(".*partial"))  # the save left no temporary behind
