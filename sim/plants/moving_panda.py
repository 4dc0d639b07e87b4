"""The arm-dynamics twin's "real" arm under its old name: it now drives any arm
(sim/plants/moving_arm.py: the simulation; sim/plants/arm_plant.py: excitation box, gains,
the plant's spec; sim/plants/arm_reality.py: the sensor and drive effects). Kept so that
existing imports work; new code imports from those modules."""

from __future__ import annotations

from serpar.sim.plants.arm_plant import AMPLITUDE, CENTRE_Q, KD, KP
from serpar.sim.plants.arm_reality import STRIBECK_SMOOTHING, Reality, SensorNoise
from serpar.sim.plants.moving_arm import TwinRun, excitation, simulate

__all__ = ["AMPLITUDE", "CENTRE_Q", "KD", "KP", "STRIBECK_SMOOTHING", "Reality", "SensorNoise",
           "TwinRun", "excitation", "simulate"]
