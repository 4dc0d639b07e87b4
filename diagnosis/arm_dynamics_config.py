"""The arm-dynamics diagnosis' configuration: smoothing, the training / held-out split, the
torque tares' form and the stick speed."""

from __future__ import annotations

from dataclasses import dataclass, field

from serpar.diagnosis.arm_dynamics_effects import STICK_VELOCITY
from serpar.diagnosis.arm_dynamics_signals import SmoothingConfig
from serpar.errors import IdentificationError

Span = tuple[float, float]

BLOCK_S = 2.0
"""Length of the alternating training / held-out time blocks [s]."""


@dataclass(frozen=True)
class ArmDynamicsConfig:
    smoothing: SmoothingConfig = field(default_factory=SmoothingConfig)
    block_s: float = BLOCK_S
    tare_knot_s: float | None = None
    """None: one constant tare per torque sensor. A spacing [s]: each sensor's tare is a
    piecewise-linear function of time with knots this far apart (the baseline then has n values
    per knot), for recordings long enough that the sensor zero's random walk shows."""
    stick_velocity: float = STICK_VELOCITY
    """[rad/s] Below this speed a joint with dry friction may be stuck (its friction anywhere in
    +-Fc): the rows weigh it as an interval."""
    train_span: Span | None = None
    heldout_span: Span | None = None
    """Seconds from the first sample: the rows (whole windows) inside ``train_span`` train and
    those inside ``heldout_span`` are held out; the resampling folds stay inside the training
    span. None (both): alternate ``block_s`` blocks of the whole recording."""

    def __post_init__(self) -> None:
        if not 0.0 < self.stick_velocity < 1.0:
            raise IdentificationError(f"ArmDynamicsConfig.stick_velocity={self.stick_velocity} "
                                      "rad/s must be in (0, 1)")
        if not self.block_s > 0:
            raise IdentificationError(f"ArmDynamicsConfig.block_s={self.block_s} must be > 0")
        if self.tare_knot_s is not None and not self.tare_knot_s > 0:
            raise IdentificationError(f"ArmDynamicsConfig.tare_knot_s={self.tare_knot_s} must be "
                                      "> 0 or None")
        if (self.train_span is None) != (self.heldout_span is None):
            raise IdentificationError("give both the training and the held-out span, or neither")
        if self.train_span is not None and self.heldout_span is not None:
            (a, b), (c, d) = self.train_span, self.heldout_span
            if not (0 <= a < b and 0 <= c < d):
                raise IdentificationError(f"spans {a}:{b} and {c}:{d} s must be start < end, >= 0")
            if a < d and c < b:
                raise IdentificationError(f"the training span {a}:{b} s and the held-out span "
                                          f"{c}:{d} s overlap; held-out rows must be unseen")
