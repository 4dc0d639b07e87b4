"""The ``link_inertial`` candidate: the links' inertial parameters differ from the model
file's (a CAD model's masses, centres of mass and inertias against the real arm's), in the
base parameters these data identify (FIGAROH's regressor -> base parameters stage).

Inverse dynamics is linear in the links' standard parameters (per link: m, m c, the inertia
about the link frame's origin; 10 each), so a change of them adds Y(q, dq, ddq) dphi to every
torque channel. Not every combination shows: a joint's first link turns about a fixed axis, a
link's mass sits on its joint's axis... A QR with column pivoting of Y over the recording's
rows keeps the independent columns (each a *base parameter*: that standard parameter plus
whatever of the dependent ones the data cannot tell from it, named after it); the others are
held at the file's values. The last link's own parameters are left to the ``payload``
candidate: a body at the flange and the last link take the same torques (an A-or-B pair the
payload's words name), so the other links' columns are tested beyond their span.

Y is evaluated at each row's windowed state (as the encoder errors are, arm_dynamics_effects.py):
a correction to a model, not the model, so the window's second-order difference is negligible
beside it; it costs rows x 10 x links inverse-dynamics calls, not every sample's.

Physical consistency (positive mass, a realisable inertia) is a property of the full standard
parameters, which base parameters do not fix; it is not tested here (an LMI search would be).
"""

from __future__ import annotations

import mujoco
import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_grouping import link_regressor_at
from serpar.diagnosis.arm_dynamics_terms import Terms
from serpar.diagnosis.family import Effect
from serpar.sim.rigid_arm import ArmDynamics

Vec = NDArray[np.float64]

NAME = "link_inertial"
STANDARD = ("m", "mx", "my", "mz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
UNITS = ("kg",) + ("kg m",) * 3 + ("kg m^2",) * 6
ZERO_COLUMN = 1e-9
"""A column this small beside the largest is round-off: no torque at all."""
RANK_TOL = 1e-6
"""A (unit) column whose part outside the others' span is below this is dependent."""


class LinkInertial:
    """The candidate's Effect and its contribution at any rows (both channels)."""

    def __init__(self, terms: Terms, dyn: ArmDynamics) -> None:
        rows = np.arange(len(terms.time))
        self.drive = link_regressor_at(dyn, terms.q, terms.dq, terms.ddq)  # rows x n x 10L
        self.link = (link_regressor_at(dyn, terms.q_link, terms.dq_link, terms.ddq_link)
                     if terms.has_link else self.drive)
        stacked = self.drive[rows].reshape(-1, self.drive.shape[2])
        norm = np.linalg.norm(stacked, axis=0)
        # a column of round-off (a mass on its joint's axis moves nothing) is not a parameter;
        # the last link's own columns are the payload candidate's (a body at the flange takes
        # the same torques): the others are tested beyond their span, so the two never trade
        last = 10 * (len(dyn.arm.link_bodies) - 1)
        usable = np.flatnonzero((norm > ZERO_COLUMN * norm.max()) & (np.arange(norm.size) < last))
        tail = stacked[:, last:] / np.maximum(norm[last:], 1e-300)
        u, sv, _ = np.linalg.svd(tail, full_matrices=False)
        span = u[:, sv > RANK_TOL * sv[0]] if sv.size and sv[0] > 0 else u[:, :0]
        rest = stacked[:, usable] / norm[usable]
        rest = rest - span @ (span.T @ rest)
        _, r, piv = scipy.linalg.qr(rest, mode="economic", pivoting=True)
        diag = np.abs(np.diag(r))
        rank = int(np.sum(diag > RANK_TOL)) if diag.size else 0
        self.columns = np.sort(usable[piv[:rank]])
        links = dyn.arm.link_bodies
        names = tuple(f"{links[c // 10]}.{STANDARD[c % 10]}" for c in self.columns)
        units = tuple(UNITS[c % 10] for c in self.columns)
        mass, reach = _scale(dyn)
        bound = np.array([{"kg": mass, "kg m": mass * reach, "kg m^2": mass * reach**2}[u]
                          for u in units])
        k = len(names)
        self.effect = Effect(
            NAME, "link inertial parameters differ from the model file's (base parameters: "
            "the combinations of link masses, first moments and inertias these data identify)",
            names, units, np.zeros(k), -bound, bound)

    def contribution(self, values: Vec, rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """(link, drive) torque [N m] of the base-parameter change ``values`` at ``rows``."""
        return (self.link[rows][:, :, self.columns] @ values,
                self.drive[rows][:, :, self.columns] @ values)

    def columns_at(self, rows: NDArray[np.int64]) -> tuple[Vec, Vec]:
        """(link, drive) torque per base parameter: params x rows x n each."""
        return (np.moveaxis(self.link[rows][:, :, self.columns], 2, 0),
                np.moveaxis(self.drive[rows][:, :, self.columns], 2, 0))


def _scale(dyn: ArmDynamics) -> tuple[float, float]:
    """The arm's moving mass [kg] and reach [m] (the largest distance of a link's frame from
    the first joint's at q = 0): the search bounds of a mass, first moment and inertia change
    are these, times reach, times reach squared (no link changes by more than the arm)."""
    m = dyn.model
    bodies = [m.body(b).id for b in dyn.arm.link_bodies]
    mass = float(sum(m.body_subtreemass[b] for b in bodies[:1])) or float(m.body_mass.sum())
    data = mujoco.MjData(m)
    mujoco.mj_kinematics(m, data)
    pos = data.xpos[bodies]
    reach = float(np.max(np.linalg.norm(pos - pos[0], axis=1))) if len(bodies) > 1 else 0.0
    return max(mass, 1.0), max(reach, 0.3)
