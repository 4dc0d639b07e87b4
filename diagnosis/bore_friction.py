"""The journal/bore friction from the insertions themselves, read through the simulator.

While a journal travels down its bore (below the entry chamfer, above the shoulder) the push
meets the bore's friction, mu times the wall's normal force, and the wrench estimate's axial
part reads it (diagnosis/task_outcomes.py ``HoleOutcome.bore_axial``: its mean over the
travel). The normal force comes from the hole's own misalignment and the arm's compliance, so
no closed form gives mu from it; the simulator does. ``serpar sim2real`` reruns the same holes
at a second mu, and per hole the real mean axial force is placed on the line through the two
reruns:

    real_h - sim_h(mu0) = x (sim_h(mu1) - sim_h(mu0)),   mu = mu0 + x (mu1 - mu0)

x by least squares over the seated holes all three saw, its sigma from the holes' scatter
about the line (contact is chaotic: two reruns of one hole differ, and that is noise here).
mu is found when the reruns show mu moves the force on these holes (the mean of
sim(mu1) - sim(mu0) beyond chance at 3 sigma's level, by Student's t) and mu lies in the
range the cell can take and lies beyond 2 sigma of mu0 (within it the simulator's mu stands:
"agrees"); otherwise it is named not identifiable, with the reason. The reruns must carry the
arm as diagnosed (checks/sim2real_bore.py ``updated_rerun``): the push also holds the arm's own physics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from serpar.diagnosis.task_outcomes import HoleOutcome

MIN_HOLES = 2
SENSITIVITY_P = 0.0027
"""The reruns must move the in-bore force beyond chance at this two-sided level (3 sigma of a
normal), by Student's t over the holes' differences."""
MU_RANGE = (0.01, 1.5)
AGREES_SIGMA = 2.0
"""A mu within this many sigma of the reruns' first (the simulator's) is no finding."""


@dataclass(frozen=True)
class BoreFriction:
    """The bore's friction as the insertions show it (``mu`` None: not identifiable)."""

    mu: float | None
    std: float | None
    holes: int
    mu_reruns: tuple[float, float]
    """The two mu the simulator ran the holes at."""
    reason: str = ""
    """Why mu is not identifiable ("" when found)."""
    agrees: bool = False
    """No mu is named because the cell's in-bore push agrees with the simulator's: at the gate
    (no rerun spent) or on the line, within 2 sigma of its mu (reason)."""

    def words(self) -> str:
        if self.agrees:
            return f"the bore's friction: {self.reason}"
        if self.mu is None:
            return f"the bore's friction: not identifiable on these holes ({self.reason})"
        return (f"the bore's friction from the in-bore push of {self.holes} holes: mu = "
                f"{self.mu:.3g} ± {self.std:.2g} (reruns at mu {self.mu_reruns[0]:.3g} and "
                f"{self.mu_reruns[1]:.3g})")

    def as_dict(self) -> dict[str, object]:
        return {"mu": self.mu, "std": self.std, "holes": self.holes,
                "mu_reruns": list(self.mu_reruns), "agrees_with_nominal": self.agrees,
                "reason": self.reason or None, "words": self.words()}


def _by_hole(outcomes: list[HoleOutcome]) -> dict[tuple[int, int | None], float]:
    return {(h.cycle, h.hole): h.bore_axial[0] for h in outcomes if h.bore_axial is not None}


def bore_friction(real: list[HoleOutcome], at_mu0: list[HoleOutcome], at_mu1: list[HoleOutcome],
                  mu0: float, mu1: float) -> BoreFriction:
    """mu from the real holes' in-bore axial force between the simulator's at ``mu0`` and ``mu1``."""
    r, a, b = _by_hole(real), _by_hole(at_mu0), _by_hole(at_mu1)
    keys = [k for k in r if k in a and k in b]
    reruns = (mu0, mu1)
    if len(keys) < MIN_HOLES:
        return BoreFriction(None, None, len(keys), reruns,
                            f"{len(keys)} seated insertion(s) with an in-bore travel in the cell "
                            f"and both reruns; {MIN_HOLES} needed")
    y = np.array([r[k] - a[k] for k in keys])
    d = np.array([b[k] - a[k] for k in keys])
    n = len(keys)
    d_sigma = float(d.std(ddof=1) / math.sqrt(n))
    t_needed = float(stats.t.ppf(1.0 - SENSITIVITY_P / 2, n - 1))
    if not abs(d.mean()) > t_needed * d_sigma:
        t = abs(d.mean()) / d_sigma if d_sigma > 0 else 0.0
        return BoreFriction(None, None, n, reruns,
                            f"mu {mu0:.3g} -> {mu1:.3g} moves the simulator's in-bore push by "
                            f"{d.mean():+.3g} ± {d_sigma:.2g} N over {n} holes (t {t:.2g}, where "
                            f"3 sigma asks {t_needed:.2g}): these holes' travel does not load "
                            "the bore's wall enough to read its friction")
    x = float(d @ y / (d @ d))
    scatter = float(np.sqrt(np.sum((y - x * d) ** 2) / (n - 1)))
    mu = mu0 + x * (mu1 - mu0)
    std = scatter / math.sqrt(float(d @ d)) * abs(mu1 - mu0)
    if not MU_RANGE[0] <= mu <= MU_RANGE[1]:
        return BoreFriction(None, None, n, reruns,
                            f"the real push reads mu = {mu:.3g} ± {std:.2g}, outside "
                            f"{MU_RANGE[0]:g}..{MU_RANGE[1]:g}: not the bore's friction alone")
    if abs(mu - mu0) <= AGREES_SIGMA * std:  # no change to name: the simulator's mu stands
        return BoreFriction(None, None, n, reruns,
                            f"the in-bore push of {n} holes reads mu = {mu:.3g} ± {std:.2g}, "
                            f"within {AGREES_SIGMA:g} sigma of the simulator's {mu0:.3g}",
                            agrees=True)
    return BoreFriction(mu, std, n, reruns)
