"""``serpar bench --montecarlo``: insertion trials per second, their scaling with threads, the
batched loop against bare ``mujoco.batch`` stepping of the same trial scenes (the floor), and
what building a trial's scene costs in place and built ahead in processes (checks/build_ahead.py:
a GPU batch of thousands of worlds waits for all its scenes)."""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial

import mujoco
import mujoco.batch
import numpy as np

from serpar.checks.build_ahead import BuildAhead
from serpar.checks.montecarlo import build_trial, prepare, run_block, scene_config
from serpar.checks.montecarlo_config import MonteCarloConfig
from serpar.sim.arm import HOME_Q
from serpar.sim.trial_scene import TrialIds
from serpar.tasks.insertion_batch import TrialConfig
from serpar.tasks.trial_start import write_start


def _physics_steps(rows: list, timestep: float) -> int:
    settle = TrialConfig().settle_s
    return int(sum(round((r.result.sim_time_s + settle) / timestep) for r in rows))


def bare_rate(cfg: MonteCarloConfig, trials: int, seed: int, threads: int, steps: int = 2000) -> float:
    """Summed steps/s of bare ``Batch.rollout`` on the same trial scenes from their starts (the
    arm held by its gravity torques, no controller): what the physics alone costs."""
    models, starts, _ = prepare(cfg, seed, range(trials), np.array(HOME_Q))
    ids = TrialIds.of(models[0])
    batch = mujoco.batch.Batch(models[0], trials, threads)
    batch.set_models(models)
    qpos = batch.bind("qpos")
    bias = batch.bind("qfrc_bias")
    batch.reset(stage=mujoco.mjtStage.mjSTAGE_NONE)
    for i, st in enumerate(starts):
        write_start(qpos[i], ids, st)
    batch.forward()
    batch.bind("ctrl")[:, ids.arm_actuators] = bias[:, ids.arm_dof]
    t0 = time.perf_counter()
    batch.rollout(steps, record=())
    return trials * steps / (time.perf_counter() - t0)


def build_ms(cfg: MonteCarloConfig, trials: int, seed: int, workers: int) -> float:
    """Wall ms per trial scene (drawn, compiled, its start planned) handed to the runner: in
    place (``workers`` 1) or built ahead on ``workers`` processes, their start-up included."""
    t0 = time.perf_counter()
    if workers < 2:
        for k in range(trials):
            build_trial(cfg, seed, k)
    else:
        with BuildAhead(partial(build_trial, cfg, seed), 0, trials, workers) as ahead:
            for k in range(trials):
                ahead.get(k)
    return 1e3 * (time.perf_counter() - t0) / trials


def montecarlo_bench(trials: int = 32, threads: tuple[int, ...] = (1, 2), seed: int = 0,
                     tick: Callable[[str], None] = lambda name: None) -> dict[str, object]:
    """One batch of ``trials`` trials per thread count: trials/s, physics steps/s summed over
    the batch, and the same against bare stepping (overhead = bare / loop)."""
    cfg = MonteCarloConfig()
    timestep = scene_config(cfg).physics.timestep
    out: dict[str, object] = {"trials": trials, "by_threads": {}}
    for n in threads:
        t0 = time.perf_counter()
        rows = run_block(cfg, seed, 0, trials, n, slots=trials)
        wall = time.perf_counter() - t0
        steps = _physics_steps(rows, timestep)
        bare = bare_rate(cfg, trials, seed, n)
        out["by_threads"][str(n)] = {  # type: ignore[index]
            "wall_s": wall, "trials_per_s": trials / wall, "steps_per_s": steps / wall,
            "bare_steps_per_s": bare, "overhead": bare / (steps / wall)}
        tick(f"montecarlo, {n} thread(s)")
    rates = {k: v["trials_per_s"] for k, v in out["by_threads"].items()}  # type: ignore[union-attr]
    first = rates[str(threads[0])]
    out["scaling"] = {k: v / first for k, v in rates.items()}
    workers = max(threads)
    out["scene_build_ms"] = {str(w): build_ms(cfg, 4 * trials, seed, w) for w in sorted({1, workers})}
    tick("montecarlo, scene builds")
    return out

