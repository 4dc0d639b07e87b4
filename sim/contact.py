"""Contact force sums between groups of geoms (for scoring and checks, not for control)."""

from __future__ import annotations

from collections.abc import Collection

import mujoco
import numpy as np


def contact_force_on(model: mujoco.MjModel, data: mujoco.MjData, geoms: Collection[int],
                     others: Collection[int] | None = None) -> np.ndarray:
    """Total contact force [N, world frame] that `others` (default: anything) exert on `geoms`."""
    total = np.zeros(3)
    f6 = np.zeros(6)
    for i in range(data.ncon):
        c = data.contact[i]
        if c.geom2 in geoms and (others is None or c.geom1 in others):
            sign = 1.0  # the contact force acts on geom2 along the frame normal
        elif c.geom1 in geoms and (others is None or c.geom2 in others):
            sign = -1.0
        else:
            continue
        mujoco.mj_contactForce(model, data, i, f6)
        total += sign * c.frame.reshape(3, 3).T @ f6[:3]
    return total


def body_geoms(model: mujoco.MjModel, body_id: int) -> set[int]:
    """Geom ids of one body."""
    start = model.body_geomadr[body_id]
    return set(range(start, start + model.body_geomnum[body_id]))
