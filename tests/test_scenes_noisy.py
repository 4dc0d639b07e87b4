"""Check 4 (menagerie's model test): every scene, stepped 2 s with noisy control, stays clean."""

import pytest

from serpar.sim.scene_noise import NOISY_SCENES, step_with_noise


@pytest.mark.parametrize("scene", NOISY_SCENES)
def test_scene_steps_2s_with_noise_without_warnings(scene):
    assert step_with_noise(scene, seconds=2.0, seed=1) == []
