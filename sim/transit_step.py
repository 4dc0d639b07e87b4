"""A longer physics step while nothing precise can happen: the cell's transit.

The 0.1 ms step is what the journal/bore contact needs (sim/physics.py: its solref time
constant is 2 steps, its penetration well under a micrometre). Most of a hole cycle, though, is
free travel: the empty hand to the tray, the part carried to the inspection station and on to
the plate. There the cell steps at ``PhysicsConfig.transit_timestep`` (0.25 ms, 4 substeps per
control period) and returns to the 0.1 ms step before anything can reach the plate or the tray
(the collision gate decides both, sim/collision_gate.py), so every contact between a journal
and a bore, every grasp and every release happens at the exact step. The Stewart platform
moves only at the fine step: its stiff leg servos (40 Hz) settle 0.45 um elsewhere at 0.25 ms,
so the transit step needs the platform asleep with no wake pending, checked every period.

What depends on the step is kept physically the same:
- the pads' normal time constant is 0.5 ms either way (5 fine steps = 2 transit steps, the
  stiffest MuJoCo allows at 0.25 ms): the transit step may not be longer than half of it;
- the pads' friction rows: a part held on the arm's chain drifts in the pads at
  Jdot*qvel * (1/b - h/2) (sim/physics.py, ``grip_friction_damping``); at the transit step b
  is chosen to give the same drift as the fine step's b (b*h = 1.76 at 0.25 ms, under the
  stability limit 2).
- the motion: the velocities are re-staggered at each switch (:func:`restagger`), or the
  encoders would read a one-period acceleration 7.5 % off there.
A model whose actuators or sensors keep a history (a delay in steps: a diagnosed plant) stays
at the fine step.
"""

from __future__ import annotations

import mujoco
import numpy as np

from serpar.sim.arm import PAD_GEOMS
from serpar.sim.names import ARM, STEWART
from serpar.sim.physics import AWAKE, PhysicsConfig


class TransitStep:
    """Switches a compiled cell between the fine step and the transit step."""

    def __init__(self, model: mujoco.MjModel, physics: PhysicsConfig) -> None:
        self.physics = physics
        self.transit = False
        self.bind(model)

    def bind(self, model: mujoco.MjModel) -> None:
        """A freshly compiled model: at the fine step, as compiled."""
        self.model = model
        pads = [model.geom(ARM + p).id for p in PAD_GEOMS]
        self._pairs = np.flatnonzero(np.isin(model.pair_geom1, pads) | np.isin(model.pair_geom2, pads))
        self._fine_friction = model.pair_solreffriction[self._pairs].copy()
        delayed = bool(np.any(model.actuator_history[:, 0])) or bool(np.any(model.sensor_history[:, 0]))
        self.available = self.physics.transit_timestep is not None and not delayed
        self.transit = False
        bodies = [b for b in range(model.nbody) if model.body(b).name.startswith(STEWART)]
        self._platform_bodies = np.array(bodies, int)
        self._platform_dofs = np.flatnonzero(np.isin(model.dof_bodyid, bodies))

    def platform_still(self, data: mujoco.MjData) -> bool:
        """The Stewart platform asleep with no wake pending (a new leg command wakes it with a
        1e-30 m/s nudge, sim/physics.py): its servo and legs move only at the fine step."""
        return not (np.any(data.body_awake[self._platform_bodies] == AWAKE)
                    or np.any(data.qvel[self._platform_dofs]))

    def set(self, transit: bool, data: mujoco.MjData | None = None) -> bool:
        """Step at the transit step (True) or the fine one; returns whether it changed.
        ``data`` (the state about to be stepped) gets its velocities re-staggered for the new
        step (:func:`restagger`); without it (a state restored from a snapshot) they are kept."""
        transit = transit and self.available
        if transit == self.transit:
            return False
        m, p = self.model, self.physics
        old_step = m.opt.timestep
        if transit:
            assert p.transit_timestep is not None
            m.opt.timestep = p.transit_timestep
            m.pair_solreffriction[self._pairs] = p.transit_grip_solreffriction
        else:
            m.opt.timestep = p.timestep
            m.pair_solreffriction[self._pairs] = self._fine_friction
        if data is not None:
            restagger(m, data, old_step, m.opt.timestep)
        self.transit = transit
        return True


def restagger(model: mujoco.MjModel, data: mujoco.MjData, old_step: float, new_step: float) -> None:
    """Carry a semi-implicit Euler state over a change of step. The step kicks the velocity,
    then moves the positions with it, so the velocity a step leaves is the motion's at half
    that step before its end; the next step's kick assumes half *its* step. Switching from h1
    to h2 without moving the velocity by qacc (h1 - h2) / 2 puts qacc (h2 - h1) / 2 into it:
    the positions then read, over the control period after the switch, an acceleration
    (h2 - h1) / (2 T) too large (7.5 % at 0.1 -> 0.25 ms in 1 ms periods; on the arm, a
    one-sample spike of up to 1 N m in what a recorded episode's encoders imply, against
    torque sensors that show none). Measured and tested in tests/test_transit_step.py."""
    awake = data.body_awake[model.dof_bodyid] == AWAKE  # a sleeping tree keeps its rest
    data.qvel[awake] -= 0.5 * (new_step - old_step) * data.qacc[awake]
