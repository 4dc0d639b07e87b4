"""Stewart loop-closure measurement in the full cell (baseplate payload on, arm held)."""

from __future__ import annotations

import mujoco
import numpy as np

from serpar.sim import names
from serpar.sim.physics import PhysicsConfig, wake_tree_of
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.stewart import loop_site_ids, loop_violation


def loop_hold_and_stroke(
    physics: PhysicsConfig = PhysicsConfig(), rest_s: float = 0.3, ramp_s: float = 1.5,
    low: float = 0.002, high: float = 0.0488,
) -> tuple[float, float]:
    """Max loop violation [m] while holding home, then over a full-stroke ramp of all legs.

    The ramp is a smooth (cosine) pure-Z motion from stroke `low` to `high`.
    """
    scene = build_scene(SceneConfig(n_conductors=0, physics=physics))
    m, d = scene.model, scene.data
    sites = loop_site_ids(m, names.STEWART)
    dt = m.opt.timestep
    rest = 0.0
    for _ in range(round(rest_s / dt)):
        scene.gravity_hold_arm()
        mujoco.mj_step(m, d)
        rest = max(rest, loop_violation(m, d, site_ids=sites))
    start = d.ctrl[scene.leg_actuators].copy()
    platform_dof = m.body_dofadr[m.body(names.STEWART + "platform").id]
    motion = 0.0
    settle = round(0.5 / dt)  # first move from home to the low end, then the full stroke
    n = round(ramp_s / dt)
    for i in range(settle + n + settle):
        if i < settle:
            target = start + (low - start) * 0.5 * (1 - np.cos(np.pi * i / settle))
        else:
            u = min(1.0, (i - settle) / n)
            target = np.full(6, low + (high - low) * 0.5 * (1 - np.cos(np.pi * u)))
        wake_tree_of(d, platform_dof)  # the still platform may have fallen asleep
        d.ctrl[scene.leg_actuators] = target
        scene.gravity_hold_arm()
        mujoco.mj_step(m, d)
        motion = max(motion, loop_violation(m, d, site_ids=sites))
    return rest, motion
