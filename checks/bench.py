"""`serpar bench`, physics part: how fast the cell steps, bare and under serpar's control loop.

Every rate is the best of `repeats` timings (the least disturbed by the machine), in physics
steps per wall second; real-time factor = simulated seconds per wall second. The loop figures
are timed from a saved state, then bare `mj_step` is timed from the same state replaying the
controls the loop wrote: their ratio is the loop's overhead on the floor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from serpar.checks.arm_checks import DOWN, press_setup
from serpar.controllers.arm_controller import ArmController, ControlLaw, controller_config
from serpar.controllers.arm_laws import CartesianTarget, ForceTarget
from serpar.controllers.cell_runtime import CellRuntime
from serpar.controllers.trajectory import LineMove
from serpar.errors import ConfigError
from serpar.sim.physics import PhysicsConfig
from serpar.sim.scene import Scene, SceneConfig, build_scene


@dataclass(frozen=True)
class BenchConfig:
    sim_seconds: float = 0.2
    """Simulated time per timing [s]."""
    repeats: int = 3
    settle_s: float = 0.6
    """Let the tray's conductors come to rest (and fall asleep) before timing [s]."""

    def __post_init__(self) -> None:
        if not 0.01 <= self.sim_seconds <= 10 or not 1 <= self.repeats <= 20:
            raise ConfigError("bench: sim_seconds in 0.01..10, repeats in 1..20")


@dataclass(frozen=True)
class Rate:
    steps_per_s: float
    realtime_factor: float

    def as_dict(self) -> dict[str, float]:
        return {"steps_per_s": self.steps_per_s, "realtime_factor": self.realtime_factor}


def _best(run: Callable[[], None], restore: Callable[[], None], steps: int, dt: float, repeats: int) -> Rate:
    best = np.inf
    for _ in range(repeats):
        restore()
        t0 = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - t0)
    return Rate(steps / best, steps * dt / best)


def _snapshot(scene: Scene) -> Callable[[], None]:
    saved = mujoco.MjData(scene.model)
    mujoco.mj_copyData(saved, scene.model, scene.data)
    return lambda: mujoco.mj_copyData(scene.data, scene.model, saved)


def bare_rate(scene_config: SceneConfig, cfg: BenchConfig) -> Rate:
    """mj_step alone on a cell at rest, controls holding the arm against gravity."""
    scene = build_scene(scene_config)
    m, d = scene.model, scene.data
    for _ in range(round(cfg.settle_s / m.opt.timestep)):
        mujoco.mj_step(m, d)
    n = round(cfg.sim_seconds / m.opt.timestep)

    def run() -> None:
        for _ in range(n):
            mujoco.mj_step(m, d)

    return _best(run, _snapshot(scene), n, m.opt.timestep, cfg.repeats)


def _loop_vs_bare(rt: CellRuntime, command: Callable[[float], None], cfg: BenchConfig) -> dict[str, object]:
    """serpar's control loop (`CellRuntime.step`: sensors, wrench estimate, control law, gripper,
    collision gate, health check), then bare `mj_step` replaying the loop's own controls and
    gate decisions from the same state (the same trajectory bit for bit, contacts and sleeping:
    the ratio is the loop's own cost), then the same replay on the cell as built (every geom
    in the broad phase: what the gate saves). Frozen controls would let the arm drift off its
    contact: a cheaper, other simulation."""
    m, d = rt.scene.model, rt.scene.data
    gate = rt.gate
    assert gate is not None
    periods, substeps = round(cfg.sim_seconds / rt.dt), rt.arm.substeps
    motors = rt.arm.index.actuators
    n = periods * substeps
    saved = mujoco.MjData(m)
    mujoco.mj_copyData(saved, m, d)
    controls, gated = np.empty((periods, m.nu)), np.empty((periods, len(gate.groups)), bool)

    def restore() -> None:
        mujoco.mj_copyData(d, m, saved)
        rt.reset_health()

    def loop() -> None:
        for k in range(periods):
            command(k * rt.dt)
            rt.step()
            controls[k] = d.ctrl
            gated[k] = [g.on for g in gate.groups]

    def replay(with_gate: bool) -> Callable[[], None]:
        def run() -> None:
            held = saved.ctrl.copy()
            for k in range(periods):
                if with_gate:
                    gate.set_on(gated[k])
                d.ctrl[:] = controls[k]
                d.ctrl[motors] = 0.5 * (held[motors] + controls[k][motors])  # the centred switch
                mujoco.mj_step(m, d)
                d.ctrl[:] = controls[k]
                mujoco.mj_step(m, d, nstep=substeps - 1)
                held = controls[k]
        return run

    looped = _best(loop, restore, n, m.opt.timestep, cfg.repeats)
    end = d.qpos.copy()
    floor = _best(replay(True), restore, n, m.opt.timestep, cfg.repeats)
    identical = bool(np.array_equal(end, d.qpos))
    built = _best(replay(False), restore, n, m.opt.timestep, cfg.repeats)
    return {"loop": looped.as_dict(), "bare": floor.as_dict(), "bare_as_built": built.as_dict(),
            "overhead": floor.steps_per_s / looped.steps_per_s,
            "vs_as_built": built.steps_per_s / looped.steps_per_s,
            "replay_identical": identical, "gated_share": float(1 - gated.mean())}


def _runtime(scene: Scene, ctrl: ArmController) -> CellRuntime:
    return CellRuntime.create(scene, ctrl.config, seed=0, arm=ctrl, transit=False)  # steps/s at the fine step


def free_motion(cfg: BenchConfig) -> dict[str, object]:
    """The full default cell; the arm moves 0.1 m along a line under impedance control."""
    scene = build_scene(SceneConfig())
    m, d = scene.model, scene.data
    ctrl = ArmController(m, "arm/", controller_config(True))
    ctrl.hold_joints(d.qpos[scene.arm_qpos_adr].copy())
    for _ in range(round(cfg.settle_s / ctrl.dt)):
        ctrl.step(m, d)
    pos, rot = ctrl.nominal.tcp_pose()
    move = LineMove(pos, pos + np.array([0.05, 0.08, -0.03]), rot, cfg.sim_seconds)
    rt = _runtime(scene, ctrl)
    return _loop_vs_bare(rt, lambda t: ctrl.track(move.at(t), ControlLaw.IMPEDANCE), cfg)


def in_contact(cfg: BenchConfig) -> dict[str, object]:
    """The full default cell with a grasped conductor's journal pushed on the plate at 5 N by
    the direct force-position law (a contact-rich phase like the insertion's)."""
    scene, ctrl, contact_tcp = press_setup(True, scene_config=SceneConfig(n_conductors=36))
    m, d = scene.model, scene.data
    rot = d.site_xmat[m.site("arm/tcp").id].reshape(3, 3).copy()
    held = CartesianTarget(contact_tcp - np.array([0, 0, 5e-4]), rot)
    force = ForceTarget(DOWN, 5.0)
    rt = _runtime(scene, ctrl)
    rt.gripper.grasp(20.0)  # the squeeze press_setup set
    # 1.5 s: the law starts 1 mm above the plate; the speed-limited approach lands at ~3 mm/s,
    # the push overshoots to ~7 N and settles to 5 N within ~1 s.
    for _ in range(round(max(cfg.settle_s, 1.5) / ctrl.dt)):
        ctrl.track(held, ControlLaw.FORCE_POSITION, force)
        rt.step()
    push = ctrl.measured_push()
    report = _loop_vs_bare(rt, lambda t: ctrl.track(held, ControlLaw.FORCE_POSITION, force), cfg)
    return {**report, "push_n": push}


def run_bench(cfg: BenchConfig = BenchConfig(), tick: Callable[[str], None] = lambda name: None
              ) -> dict[str, object]:
    out: dict[str, object] = {"timestep_s": PhysicsConfig().timestep, "sim_seconds": cfg.sim_seconds,
                              "repeats": cfg.repeats, "bare": {}}
    bare = out["bare"]
    assert isinstance(bare, dict)
    for name, scene_cfg in (("cell_36_conductors", SceneConfig()),
                            ("cell_36_conductors_no_sleep", SceneConfig(physics=replace(PhysicsConfig(), sleep=False))),
                            ("cell_empty_tray", SceneConfig(n_conductors=0))):
        bare[name] = bare_rate(scene_cfg, cfg).as_dict()
        tick(name)
    out["free_motion"] = free_motion(cfg)
    tick("free_motion")
    out["in_contact"] = in_contact(cfg)
    tick("in_contact")
    return out
