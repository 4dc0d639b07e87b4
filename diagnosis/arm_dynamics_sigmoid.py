"""Joint friction in the published form of Gaz et al. (IEEE RA-L 2019, the Panda's identified
model; :data:`serpar.sim.arm.GAZ_FRICTION_PHI`) as a candidate of the arm-dynamics diagnosis:

    tau_f(v) = phi1 (sigma(phi2 (v + phi3)) - sigma(phi2 phi3))

per joint, the drive losing it. At speed it is a Coulomb level phi1 / 2 about an offset (the
sigmoid is centred on -phi3, not on zero); it passes through zero torque at rest, with a
slope phi1 phi2 / 4 there, so it has no stiction band. The windowed regressor is evaluated at
the asked rows from the full-rate velocity of each window (the channels' own windowing), and
its derivatives by phi1..phi3 are exact (the fit's Jacobian takes them, not differences).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.special import expit

from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.diagnosis.memo import Memo

Vec = NDArray[np.float64]

NAME = "sigmoid_friction"
STEEPNESS = (1.0, 100.0)
"""[s/rad] Range of phi2: the transition speed 1 / phi2 between 1 rad/s (a sigmoid slower
than the excitation's speeds is viscous friction) and 0.01 rad/s (the speed below which a
joint may be stuck and the encoders' velocity has no certain sign; the Panda's: 0.06-0.2)."""
SHIFT = 0.3
"""[rad/s] Largest |phi3|, the sigmoid's centre off zero speed (the Panda's: <= 0.05)."""


def sigmoid_effect(n: int, coulomb_max: float) -> Effect:
    """The candidate for n joints; ``coulomb_max`` [N m]: the arm's largest Coulomb level
    (phi1 is twice the level, the swing from one side to the other)."""
    j = range(1, n + 1)
    names = (tuple(f"phi1_{i}" for i in j) + tuple(f"phi2_{i}" for i in j)
             + tuple(f"phi3_{i}" for i in j))
    units = ("N m",) * n + ("s/rad",) * n + ("rad/s",) * n
    # phi1 starts off zero: at phi1 = 0 the other two have no gradient
    x0 = np.r_[np.full(n, 0.1 * coulomb_max), np.full(n, 10.0), np.zeros(n)]
    lower = np.r_[np.zeros(n), np.full(n, STEEPNESS[0]), np.full(n, -SHIFT)]
    upper = np.r_[np.full(n, 2.0 * coulomb_max), np.full(n, STEEPNESS[1]), np.full(n, SHIFT)]
    return Effect(NAME, "joint friction in the published sigmoid form (Gaz et al. 2019: "
                  "phi1 (sigma(phi2 (v + phi3)) - sigma(phi2 phi3)) per joint, inside the drive: "
                  "a Coulomb level phi1 / 2 at speed about an offset, zero at rest)",
                  names, units, x0, lower, upper,
                  physical_lower=(True,) * n + (False,) * (2 * n),
                  amplitude_of=(-1,) * n + 2 * tuple(range(n)))


class SigmoidFriction:
    """The sigmoid friction's drive torque and its exact derivatives at given rows."""

    def __init__(self, terms: Terms) -> None:
        rows = terms.rows
        idx = rows.centre[:, None] + np.arange(-rows.half, rows.half + 1)[None, :]
        self.velocity = terms.dq_full[idx]  # rows x window x n
        self.kernel = rows.kernel
        self.weight = float(np.sum(rows.kernel))
        self.n = terms.n
        self._memo: Memo[Vec] = Memo()

    def _split(self, p: Vec) -> tuple[Vec, Vec, Vec]:
        n = self.n
        return p[:n], p[n:2 * n], p[2 * n:]

    def torque(self, p: Vec, rows: NDArray[np.int64]) -> Vec:
        """rows x n: the friction torque the drive loses, windowed like the drive channel
        (kept for the last few ``p``: read-only)."""
        return self._memo(lambda: self._torque(p, rows), p, rows)

    def _torque(self, p: Vec, rows: NDArray[np.int64]) -> Vec:
        phi1, phi2, phi3 = self._split(p)
        s = expit(phi2 * (self.velocity[rows] + phi3))
        out = phi1 * (np.einsum("rmj,m->rj", s, self.kernel) - self.weight * expit(phi2 * phi3))
        out.flags.writeable = False
        return out

    def columns(self, p: Vec, rows: NDArray[np.int64]) -> Vec:
        """3n x rows x n: d torque / d (phi1, phi2, phi3), each on its own joint's channel."""
        phi1, phi2, phi3 = self._split(p)
        n, k = self.n, len(rows)
        v = self.velocity[rows] + phi3
        s = expit(phi2 * v)
        slope = s * (1.0 - s)
        s0 = expit(phi2 * phi3)
        slope0 = s0 * (1.0 - s0)
        w = self.weight
        d1 = np.einsum("rmj,m->rj", s, self.kernel) - w * s0
        d2 = phi1 * (np.einsum("rmj,m->rj", slope * v, self.kernel) - w * slope0 * phi3)
        d3 = phi1 * phi2 * (np.einsum("rmj,m->rj", slope, self.kernel) - w * slope0)
        out = np.zeros((3 * n, k, n))
        j = np.arange(n)
        for block, d in enumerate((d1, d2, d3)):
            out[block * n + j, :, j] = d.T
        return out
