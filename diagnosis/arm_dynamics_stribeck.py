"""The Stribeck fall of the arm-dynamics diagnosis (``stribeck_friction``): per joint
dFs sign(v) exp(-(v / vs)^2) against the motion, each joint with its own speed vs. The
regressor is tabulated on the grid :data:`STRIBECK_SPEEDS` (windowed like the drive channel)
and interpolated in log speed; its derivatives by dFs and by each speed are exact for that
interpolant (the fit's Jacobian takes them, not differences)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_library import STRIBECK_SPEEDS
from serpar.diagnosis.arm_dynamics_signals import Rows

Vec = NDArray[np.float64]

LOG_SPEEDS = np.log(STRIBECK_SPEEDS)


class StribeckFall:
    """The tabulated regressor (speeds x rows x n) of one recording."""

    def __init__(self, rows: Rows, velocity: Vec, moving: NDArray[np.bool_]) -> None:
        signed = np.sign(velocity) * moving
        self.table = np.stack([rows.at(signed * np.exp(-(velocity / vs) ** 2))
                               for vs in STRIBECK_SPEEDS])
        self.n = int(velocity.shape[1])

    def _bracket(self, speeds: Vec, rows: NDArray[np.int64]) -> tuple[Vec, Vec, Vec, Vec]:
        """(below, above, weight, step): the grid's two neighbours of each joint's speed at
        the rows, the interpolation weight and the grid step in log speed."""
        x = np.log(np.clip(speeds, STRIBECK_SPEEDS[0], STRIBECK_SPEEDS[-1]))
        k = np.clip(np.searchsorted(LOG_SPEEDS, x) - 1, 0, len(LOG_SPEEDS) - 2)
        j, r = np.arange(self.n), rows[:, None]
        step = LOG_SPEEDS[k + 1] - LOG_SPEEDS[k]
        return self.table[k, r, j], self.table[k + 1, r, j], (x - LOG_SPEEDS[k]) / step, step

    def regressor(self, speeds: Vec, rows: NDArray[np.int64]) -> Vec:
        """rows x n: the fall of unit dFs at each joint's speed."""
        lo, hi, w, _ = self._bracket(speeds, rows)
        return (1.0 - w) * lo + w * hi

    def columns(self, p: Vec, rows: NDArray[np.int64], stuck: Vec) -> tuple[Vec, Vec]:
        """(drive, band), each 2n x rows x n: the derivatives of dFs x :meth:`regressor` by
        dFs and by each joint's speed; ``stuck``: the rows' stuck weight (rows x n), whose
        band the dFs widen."""
        n = self.n
        excess, speeds = p[:n], p[n:]
        lo, hi, w, step = self._bracket(speeds, rows)
        inside = (speeds > STRIBECK_SPEEDS[0]) & (speeds < STRIBECK_SPEEDS[-1])  # clip: flat
        per_speed = np.where(inside, 1.0 / np.where(inside, speeds, 1.0), 0.0)  # d log v / d v
        j = np.arange(n)
        drive, band = np.zeros((2 * n, len(rows), n)), np.zeros((2 * n, len(rows), n))
        drive[j, :, j] = ((1.0 - w) * lo + w * hi).T
        drive[n + j, :, j] = (excess * (hi - lo) / step * per_speed).T
        band[j, :, j] = (stuck * np.sign(excess)).T
        return drive, band
