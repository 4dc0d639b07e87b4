"""The torque sensors' period mean (controllers/arm_sensors.py TorqueADC) of a sensor with a
MuJoCo ``delay``: its lag as the diagnosis reads it (a Hann-windowed period-mean difference
against the undelayed sensor, over the windowed rate) is the delay, at both physics steps.

The extrapolating ends of the undelayed ADC straddle a delayed command switch: at the 0.1 ms
step a 0.712 ms lag read as 0.709 ms and 0.817 ms as 0.796 ms (concealed cells read 3 us
early); the history's trapezoid reads both within 0.1 %. Undelayed sensors on an arm whose
actuators act late read as the plain trapezoid with the period's true end does, to 1 us."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.signal import windows

from serpar.controllers.arm_sensors import TorqueADC
from serpar.sim.arm import ARM_XML, HOME_Q
from serpar.sim.arm_drive import ArmIndex
from serpar.sim.plants.arm_changes import ArmPlantChanges, apply_arm_plant

PERIOD = 1e-3
SECONDS = 4.0


def _run(changes: ArmPlantChanges, dt: float, with_model: bool = True
         ) -> tuple[np.ndarray, np.ndarray]:
    """tau_J period means (periods x 7) and the substep samples (periods x substeps x 7) of the
    gravity-free arm under a 1 kHz staircase command (smooth sines held per period, a PD
    holding the home pose), switched as the runtime does."""
    spec = mujoco.MjSpec.from_file(str(ARM_XML))
    spec.option.timestep = dt
    spec.option.gravity = [0.0, 0.0, 0.0]
    apply_arm_plant(spec, changes, 1e-4)
    model = spec.compile()
    data = mujoco.MjData(model)
    index = ArmIndex.from_model(model)
    data.qpos[index.qpos] = HOME_Q
    substeps = round(PERIOD / dt)
    adc = TorqueADC(index, substeps, model if with_model else None)
    rng = np.random.default_rng(0)
    freq, amp, phase = rng.uniform(0.5, 4.0, (3, 7)), rng.uniform(0.5, 2.0, (3, 7)), rng.uniform(0, 6.3, (3, 7))
    out, samples, held = [], [], np.zeros(7)
    for k in range(round(SECONDS / PERIOD)):
        q, dq = data.qpos[index.qpos], data.qvel[index.dof]
        new = (amp * np.sin(2 * np.pi * freq * k * PERIOD + phase)).sum(axis=0) \
            - 40.0 * (q - HOME_Q) - 4.0 * dq
        period = []
        for s in range(substeps):
            data.ctrl[index.actuators] = 0.5 * (held + new) if s == 0 else new
            mujoco.mj_step(model, data)
            adc.sample(data, s, model if with_model else None)
            period.append(data.sensordata[np.asarray(index.torque_adr)].copy())
        if adc.reads_period_end:  # as the runtime does (controllers/cell_runtime.py)
            mujoco.mj_forward(model, data)
            adc.end(data)
        held = new
        out.append(adc.mean())
        samples.append(period)
    return np.array(out), np.array(samples)


def _period_means(delay: float, dt: float, with_model: bool = True) -> np.ndarray:
    """The ADC's period means with the torque sensors ``delay`` late."""
    return _run(ArmPlantChanges(torque_sensor_delay=delay), dt, with_model)[0]


def _lag_read(delayed: np.ndarray, undelayed: np.ndarray) -> float:
    """The lag the diagnosis's first-order model reads: windowed difference over windowed rate."""
    kernel = windows.hann(53)[1:-1]
    kernel /= kernel.sum()

    def window(x: np.ndarray) -> np.ndarray:
        return np.stack([np.convolve(c, kernel, mode="valid") for c in x.T], axis=1)

    diff = window(delayed) - window(undelayed)
    rate = -window(np.gradient(undelayed, axis=0) / PERIOD)
    return float((diff * rate).sum() / (rate * rate).sum())


@pytest.mark.parametrize("dt", [1e-4, 2.5e-4])
def test_a_delayed_sensor_reads_its_delay(dt: float) -> None:
    undelayed = _period_means(0.0, dt)
    for delay in (0.5e-3, 0.7122e-3, 0.8171e-3, 1.25e-3, 1.9e-3):
        read = _lag_read(_period_means(delay, dt), undelayed)
        assert abs(read / delay - 1.0) < 1e-3, (delay, read)


def test_the_extrapolating_ends_misread_a_delayed_switch() -> None:
    """The check can fail: without the history's period end (the undelayed weights), the 0.1 ms
    step misreads 0.817 ms by over 1 %."""
    undelayed = _period_means(0.0, 1e-4)
    read = _lag_read(_period_means(0.8171e-3, 1e-4, with_model=False), undelayed)
    assert abs(read / 0.8171e-3 - 1.0) > 0.01


def _actuation_delayed(delay: float, with_model: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Undelayed sensors on an arm whose actuators act ``delay`` late: the ADC's period means
    (with the period end the runtime hands it; without the model, the extrapolated ends of an
    ADC that knows of no delay), and the
    plain trapezoid with the period's true end (the next period's first sample, which for a
    delay of a step or more the next command does not touch)."""
    means, x = _run(ArmPlantChanges(actuation_delay=delay), 1e-4, with_model)
    substeps = x.shape[1]
    w = np.full(substeps, 1.0 / substeps)
    w[0] *= 0.5
    trapezoid = (x[:-1] * w[None, :, None]).sum(axis=1) + 0.5 / substeps * x[1:, 0]
    return means[:-1], trapezoid


def test_undelayed_sensors_read_a_delayed_actuation_as_the_trapezoid_does() -> None:
    """Delays whose switch lands mid-period and in the start or end stencil (1.163, 0.85 ms at
    the 0.1 ms step) read alike, to 1 us; the extrapolated ends misread them by 12-16 us."""
    reference = _period_means(0.0, 1e-4)[:-1]
    for delay in (0.5436e-3, 0.85e-3, 1.163e-3):
        adc, trapezoid = _actuation_delayed(delay)
        gap = _lag_read(adc, reference) - _lag_read(trapezoid, reference)
        assert abs(gap) < 1e-6, (delay, gap)
    adc, trapezoid = _actuation_delayed(0.85e-3, with_model=False)
    assert _lag_read(adc, reference) - _lag_read(trapezoid, reference) < -10e-6
