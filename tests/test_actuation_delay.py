"""A drive's actuation latency (``ArmPlantChanges.actuation_delay``) acts as a continuous delay
of the 1 kHz command at any physics step: MuJoCo's zero-order hold would apply each command
from the first step at or after tick + delay, rounding 0.5436 ms up to 0.6 ms (0.1 ms step) or
0.75 ms (0.25 ms step)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from serpar.sim.arm import ACTUATOR_NAMES, ARM_XML
from serpar.sim.plants.arm_changes import ArmPlantChanges, apply_arm_plant

TICK = 1e-3
LEVELS = np.array([0.0, 1.0, 3.0, -2.0, 0.5, 4.0])  # N m, one per tick


def _impulses(delay: float, dt: float) -> np.ndarray:
    """The joint-1 drive's impulse in each tick [N m s], the command stepping every tick."""
    spec = mujoco.MjSpec.from_file(str(ARM_XML))
    spec.option.timestep = dt
    spec.option.gravity = [0.0, 0.0, 0.0]
    apply_arm_plant(spec, ArmPlantChanges(actuation_delay=delay), dt)
    model = spec.compile()
    data = mujoco.MjData(model)
    act = model.actuator(ACTUATOR_NAMES[0]).id
    steps = round(TICK / dt)
    out = np.zeros(len(LEVELS))
    for k, level in enumerate(LEVELS):
        data.ctrl[act] = level
        for _ in range(steps):
            mujoco.mj_step(model, data)
            out[k] += data.actuator_force[act] * dt
    return out


@pytest.mark.parametrize("dt", [1e-4, 2.5e-4])
@pytest.mark.parametrize("delay", [0.5436e-3, 0.9673e-3, 1.1630e-3])
def test_each_tick_gets_a_continuous_delays_impulse(delay, dt):
    shifted = np.r_[0.0, 0.0, LEVELS][: len(LEVELS) + 2]  # the command of one and two ticks ago
    whole, frac = divmod(delay, TICK)
    late = shifted[2 - int(whole): 2 - int(whole) + len(LEVELS)]
    earlier = shifted[1 - int(whole): 1 - int(whole) + len(LEVELS)]
    # within tick k the drive delivers the command of tick k-1-whole for `frac`, then k-whole's
    want = (earlier * frac + late * (TICK - frac))
    np.testing.assert_allclose(_impulses(delay, dt), want, atol=1e-12)
