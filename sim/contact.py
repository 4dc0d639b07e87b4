"""Contact force sums between groups of geoms (for scoring and checks, not for control)."""

from __future__ import annotations

from collections.abc import Collection

import mujoco
import numpy as np


class ContactForceProbe:
    """Total contact force that one group of geoms exerts on another, fast enough to read
    after every physics substep: the groups are boolean masks over the model's geoms, so the
    contacts are filtered in one vectorised pass and only the matches are resolved."""

    def __init__(self, model: mujoco.MjModel, geoms: Collection[int],
                 others: Collection[int] | None = None) -> None:
        self.model = model
        self.on = np.zeros(model.ngeom, bool)
        self.on[list(geoms)] = True
        self.by = np.ones(model.ngeom, bool)
        if others is not None:
            self.by[:] = False
            self.by[list(others)] = True
        self._f6 = np.zeros(6)

    def force(self, data: mujoco.MjData) -> np.ndarray:
        """[N, world frame] on `geoms` from `others` (default: anything)."""
        total = np.zeros(3)
        if data.ncon == 0:
            return total
        con = data.contact
        g1, g2 = con.geom1, con.geom2
        on2 = self.on[g2] & self.by[g1]  # the contact force acts on geom2 along the frame normal
        idx = np.flatnonzero(on2 | (self.on[g1] & self.by[g2]))
        adr = con.efc_address[idx]
        idx, adr = idx[adr >= 0], adr[adr >= 0]  # excluded contacts carry no force
        if not len(idx):
            return total
        if self.model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC:  # efc_force is in the contact frame
            k = np.arange(3)
            dim = con.dim[idx][:, None]  # a frictionless (condim 1) contact has the normal row only
            f = np.where(k < dim, data.efc_force[adr[:, None] + np.minimum(k, dim - 1)], 0.0)
        else:
            f = np.empty((len(idx), 3))
            for k, i in enumerate(idx):
                mujoco.mj_contactForce(self.model, data, int(i), self._f6)
                f[k] = self._f6[:3]
        sign = np.where(on2[idx], 1.0, -1.0)
        return np.einsum("n,nk,nkj->j", sign, f, con.frame[idx].reshape(-1, 3, 3))


def contact_force_on(model: mujoco.MjModel, data: mujoco.MjData, geoms: Collection[int],
                     others: Collection[int] | None = None) -> np.ndarray:
    """Total contact force [N, world frame] that `others` (default: anything) exert on `geoms`
    (one-off reads; build a :class:`ContactForceProbe` to read it repeatedly)."""
    return ContactForceProbe(model, geoms, others).force(data)


def body_geoms(model: mujoco.MjModel, body_id: int) -> set[int]:
    """Geom ids of one body."""
    start = model.body_geomadr[body_id]
    return set(range(start, start + model.body_geomnum[body_id]))
