"""Menagerie-style model test: step each scene with random actuator noise, collect warnings/NaNs."""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from serpar.errors import UnknownNameError
from serpar.sim.arm import build_arm_spec
from serpar.sim.physics import PhysicsConfig
from serpar.sim.rig import RigConfig, build_rig
from serpar.sim.scene import SceneConfig, build_scene
from serpar.sim.stewart import StewartConfig, build_stewart_spec, home_strokes


def _standalone(spec: mujoco.MjSpec, physics: PhysicsConfig) -> tuple[mujoco.MjModel, mujoco.MjData]:
    physics.apply(spec)
    model = spec.compile()
    return model, mujoco.MjData(model)


def _models(name: str, physics: PhysicsConfig):
    """(model, data, nominal-control function) of a named scene."""
    if name == "cell":
        scene = build_scene(SceneConfig(physics=physics))

        def nominal(m, d):
            scene.gravity_hold_arm()
            return d.ctrl.copy()

        return scene.model, scene.data, nominal
    if name == "rig":
        rig = build_rig(RigConfig(), physics)
        rig.place(0.0, 2e-4)
        return rig.model, rig.data, lambda m, d: np.array([0.0, 0.0, 3.0])
    if name == "arm":
        m, d = _standalone(build_arm_spec(), physics)
        arm = np.arange(7)
        return m, d, lambda m, d: np.r_[d.qfrc_bias[arm], np.zeros(m.nu - 7)]
    if name == "stewart":
        m, d = _standalone(build_stewart_spec(StewartConfig(), physics), physics)
        home = home_strokes()
        return m, d, lambda m, d: home.copy()
    raise UnknownNameError("scene", name, NOISY_SCENES)


NOISY_SCENES: tuple[str, ...] = ("cell", "rig", "arm", "stewart")
NOISE_FRACTION = 0.05
"""Noise amplitude as a fraction of each actuator's control range."""


def step_with_noise(name: str, physics: PhysicsConfig = PhysicsConfig(), seconds: float = 2.0,
                    seed: int = 0, on_step: Callable[[int], None] | None = None) -> list[str]:
    """Step scene `name` for `seconds` with nominal control + uniform noise; return the problems."""
    model, data, nominal = _models(name, physics)
    rng = np.random.default_rng(seed)
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    span = np.where(model.actuator_ctrllimited.astype(bool), hi - lo, 1.0)
    problems: list[str] = []
    for i in range(round(seconds / model.opt.timestep)):
        noise = rng.uniform(-1.0, 1.0, model.nu) * NOISE_FRACTION * span
        data.ctrl[:] = nominal(model, data) + noise
        mujoco.mj_step(model, data)
        if on_step:
            on_step(i)
        if not np.all(np.isfinite(data.qpos)) or not np.all(np.isfinite(data.qvel)):
            problems.append(f"NaN at t={data.time:.4f} s")
            break
    for k, w in enumerate(data.warning):
        if w.number:
            problems.append(f"{mujoco.mjtWarning(k).name} x{w.number}")
    return problems
