"""``serpar montecarlo --gpu``: the trials on MuJoCo Warp (float32, tasks/warp_batch.py), then
a random sample of them re-run in float64 on the CPU cores, the reference engine.

A sampled trial agrees when its float64 outcome is the GPU's. Some trials lie on an outcome
boundary, where float32 rounding alone may tip them: a sampled trial whose float64 outcome
changes when its lateral offset moves by ``BOUNDARY_SHIFT_M`` either way (the hole moved along
its error, so the tip meets the plate that much further along the same line) is a
boundary trial, and its agreement is reported apart.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable

import mujoco
import numpy as np

from serpar.checks.montecarlo import (
    MonteCarloResult,
    TrialRow,
    run_montecarlo,
    scene_config,
    trial_config,
    trial_from,
)
from serpar.checks.montecarlo_config import MonteCarloConfig
from serpar.errors import ConfigError
from serpar.sim.tolerances import BODY_H6, HOLE_H7, JOURNAL_H6
from serpar.sim.trial_scene import TrialSceneConfig, build_trial_spec
from serpar.tasks.insertion_batch import run_trials
from serpar.tasks.trial_start import TrialDraw
from serpar.tasks.warp_batch import EPA_HORIZON_EDGES, WarpBatch, check_device

BOUNDARY_SHIFT_M = 2e-6
CHECK_SAMPLE = 64
"""Trials of a GPU run re-run in float64 on the CPU by default."""


GPU_GRIP_TIMESTEPS = 20.0
"""The pads' contact time constant on the GPU, in physics steps (the cell's: 5, 0.5 ms). In
float32 the cell's stiff pads let a held part sink 5-37 um into a pad now and then, and trials
blow up once the journal meets the bore; at 2 ms float32 seats them. In float64 the softer pads
change no outcome: 200 trials of the default budget (seed 0) gave the same 200 outcomes, peak
forces within 0.1 % (1-99 %), at most 2.1 % (docs/montecarlo.md). The float64 check still runs
the cell's pads."""


GPU_ROUNDING = (0.0, 50e-6)
"""Edge radii [m] added to the part's journal and body on the GPU (``TrialSceneConfig.rounding``).
Where a cylinder's side lies almost flat on a face (a seated journal on a bore facet, the
part's body between the pads) and overlaps it a little, MuJoCo Warp's float32 collision now
and then reports the pair separated: over one trial's substeps, 594 of the 4 538
journal-facet pairs CPU MuJoCo finds (to 0.95 um deep), and once a pad's 7 um deep contact,
whose force, gone for a step, kicked the seated part (overforce at 22-38 N in 4 of 32 trials
on warp's CPU device; with the edges rounded, 24 and none). Rounded, such a contact starts as
a distance query between the shrunk, separated shapes, which float32 resolves. The journal's
own edge round (``ConductorConfig.edge_radius``, 10 um) already does that at the journal; the
body's 50 um exceeds the contact's depth at the softer GPU pads (up to ~17 um)."""


def gpu_scene(cfg: MonteCarloConfig) -> TrialSceneConfig:
    """The budget's trial scene with the world's origin at the hole (float32 resolves ~2 nm
    there), pads float32 can hold a part in (:data:`GPU_GRIP_TIMESTEPS`), the seat as a plane
    (``TrialSceneConfig.seat_plane``: MuJoCo Warp's float32 box-cylinder collision can
    misfire with the shoulder on the seat) and the part's edges rounded (:data:`GPU_ROUNDING`)."""
    scene = scene_config(cfg)
    physics = dataclasses.replace(scene.physics, grip_timesteps=GPU_GRIP_TIMESTEPS)
    return dataclasses.replace(scene, at_origin=True, physics=physics, seat_plane=True,
                               rounding=GPU_ROUNDING)


def reference_model(scene: TrialSceneConfig) -> mujoco.MjModel:
    """The model whose meshes every world shares: the thinnest journal's tip (never proud of a
    world's journal; the facets are moved per world, tasks/warp_batch.py)."""
    return build_trial_spec(scene, HOLE_H7.nominal, JOURNAL_H6.min, BODY_H6.nominal).compile()


def run_gpu(cfg: MonteCarloConfig, trials: int, seed: int, batch: int, device: str = "cuda",
            on_rows: Callable[[list[TrialRow]], None] | None = None) -> MonteCarloResult:
    """All ``trials`` on MuJoCo Warp, ``batch`` worlds at a time on ``device``."""
    check_device(device)
    scene = gpu_scene(cfg)
    reference = reference_model(scene)
    engines: list[WarpBatch] = []

    def engine(_first: mujoco.MjModel, n: int) -> WarpBatch:
        engines.append(WarpBatch(reference, n, device))
        return engines[-1]

    # a batch of thousands of worlds waits for all its scenes: build them on every core
    result = run_montecarlo(cfg, trials, seed, 1, batch, on_rows, scene=scene, engine=engine,  # type: ignore[arg-type]
                            build_workers=os.cpu_count() or 1)
    limit = sum(e.iteration_limit for e in engines)
    total = sum(e.world_periods for e in engines)
    if total:
        result.notes.append(f"MuJoCo Warp's solver stopped at its iteration limit in {limit} of {total} "
                            f"world-periods ({100 * limit / total:.1f} %; float32 short of the tolerance)")
        epa = sum(e.epa_overflow for e in engines)
        result.notes.append(f"MuJoCo Warp's EPA horizon ({EPA_HORIZON_EDGES} edges) overflowed in {epa} of "
                            f"{total} world-periods (a mesh pair without its contact for a step)")
    return result


def shifted(row: TrialRow, delta: float) -> TrialDraw:
    """The row's draw with the believed hole moved ``delta`` [m] along its error (along x for
    none): the journal tip meets the plate ``delta`` further along the same line."""
    draw = row.sample.draw
    err = np.asarray(draw.hole_error, float)
    norm = float(np.hypot(*err))
    direction = err / norm if norm > 0 else np.array([1.0, 0.0])
    return dataclasses.replace(draw, hole_error=(float(err[0] - delta * direction[0]),
                                                 float(err[1] - delta * direction[1])))


def check_sample(result: MonteCarloResult, sample_size: int = CHECK_SAMPLE, threads: int = 2,
                 rng_seed: int = 0) -> dict[str, object]:
    """Re-run a random sample of ``result``'s trials in float64 on the CPU, with each one's
    lateral offset also moved -/+ BOUNDARY_SHIFT_M; the agreement, boundary trials apart."""
    if sample_size < 1:
        raise ConfigError(f"--gpu-check {sample_size}: a sample of at least 1 trial")
    cfg, seed = result.config, result.seed
    rng = np.random.default_rng([seed, rng_seed, 31])
    rows = sorted(rng.choice(len(result.rows), size=min(sample_size, len(result.rows)), replace=False))
    picked = [result.rows[i] for i in rows]
    scene = scene_config(cfg)
    trials = []
    for row in picked:
        for delta in (0.0, -BOUNDARY_SHIFT_M, BOUNDARY_SHIFT_M):
            draw = row.sample.draw if delta == 0.0 else shifted(row, delta)
            trials.append(trial_from(cfg, draw, seed, row.trial, scene))
    cpu = run_trials(trials, scene.chamfer, trial_config(cfg), threads)
    per_trial = []
    for j, row in enumerate(picked):
        ref, minus, plus = (cpu[3 * j + i].outcome.value for i in range(3))
        per_trial.append({"trial": row.trial, "gpu": row.result.outcome.value, "cpu": ref,
                          "boundary": minus != ref or plus != ref,
                          "gpu_peak_n": row.result.peak_force_n, "cpu_peak_n": cpu[3 * j].peak_force_n})
    return agreement(per_trial)


def agreement(per_trial: list[dict[str, object]]) -> dict[str, object]:
    """Counts over the sampled trials (each: gpu and cpu outcome, whether a boundary trial)."""
    inner = [t for t in per_trial if not t["boundary"]]
    edge = [t for t in per_trial if t["boundary"]]
    same = sum(t["gpu"] == t["cpu"] for t in inner)
    return {"sampled": len(per_trial), "boundary": len(edge),
            "agree": same, "compared": len(inner),
            "agreement": same / len(inner) if inner else None,
            "boundary_agree": sum(t["gpu"] == t["cpu"] for t in edge),
            "peak_ratio_median": (float(np.median([t["gpu_peak_n"] / t["cpu_peak_n"] for t in per_trial  # type: ignore[operator]
                                                   if t["cpu_peak_n"]]))
                                  if any(t["cpu_peak_n"] for t in per_trial) else None),
            "trials": per_trial}
