"""First-pass yield by physics: N sampled insertion trials, batched (``serpar montecarlo``).

Each trial draws its part diameters and the cell's errors (checks/montecarlo_config.py) from
its own stream (seed, trial), plans its start (tasks/trial_start.py) and runs the episode's
insertion in a batch of trial scenes (tasks/insertion_batch.py). Batches run one after the
other on ``threads`` CPU threads; a result does not depend on the batch size or the thread
count. Out: the success rate with a Wilson 95 % interval, outcome counts, and per trial what
was drawn and what happened (``trials.parquet``).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import mujoco
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from serpar.checks.build_ahead import BuildAhead
from serpar.checks.montecarlo_config import SOURCES, MonteCarloConfig, TrialSample, draw_trial
from serpar.checks.tool_changer_robot import PAPER_POSITION_RELIABILITY
from serpar.controllers.batch_sensors import trial_seeds
from serpar.errors import ConfigError
from serpar.sim.arm import HOME_Q, PANDA_COULOMB_FRICTION
from serpar.sim.trial_scene import TrialIds, TrialSceneConfig, build_trial_spec
from serpar.tasks.episode_config import EpisodeConfig, Outcome, wilson_interval
from serpar.tasks.insertion import InsertionConfig
from serpar.tasks.insertion_batch import Trial, TrialConfig, TrialResult, run_trials
from serpar.tasks.ray_runner import ray_map
from serpar.tasks.trial_start import TrialDraw, TrialStart, plan_start

GPU_OR_RAY = "--gpu runs on this machine's GPU; --ray spreads CPU batches: choose one"
BATCH = 256
"""Simulations at a time (and trials per Ray task): enough that the controller's numpy work per
period is spread thin over the physics of many trials (~4 % at 2 threads)."""


@dataclass(frozen=True)
class TrialRow:
    """One trial: what was drawn and how it ended."""

    trial: int
    sample: TrialSample
    start_lateral_mm: float
    """The true journal tip off the hole axis at the start [mm]."""
    result: TrialResult

    def as_dict(self) -> dict[str, object]:
        d, r = self.sample.draw, self.result
        return {"trial": self.trial, "outcome": r.outcome.value, "reason": r.reason,
                "peak_force_n": r.peak_force_n, "lateral_misalignment_mm": r.lateral_misalignment_mm,
                "insertion_time_s": r.insertion_time_s, "depth_shortfall_mm": r.depth_shortfall_mm,
                "sim_time_s": r.sim_time_s, "start_lateral_mm": self.start_lateral_mm,
                "start_tilt_deg": float(np.degrees(self.sample.tilt)),
                "clearance_um": (d.hole_diameter - d.journal_diameter) * 1e6,
                "hole_diameter_mm": d.hole_diameter * 1e3, "journal_diameter_mm": d.journal_diameter * 1e3,
                **{f"{s}_size": self.sample.magnitude[s] for s in SOURCES}}


@dataclass
class MonteCarloResult:
    config: MonteCarloConfig
    seed: int
    trials_asked: int
    rows: list[TrialRow] = field(default_factory=list)
    wall_s: float = 0.0
    interrupted: bool = False
    errors: list[str] = field(default_factory=list)
    """Batches that did not come back (a Ray task that died), with why."""
    notes: list[str] = field(default_factory=list)
    """What the engine says of the run (MuJoCo Warp's solver at its iteration limit)."""

    @property
    def counts(self) -> dict[str, int]:
        counts = {o.value: 0 for o in Outcome}
        for r in self.rows:
            counts[r.result.outcome.value] += 1
        return {k: v for k, v in counts.items() if v or k in ("success", "jam", "align_fail", "sim_fault")}

    @property
    def success_rate(self) -> float:
        return self.counts["success"] / len(self.rows) if self.rows else float("nan")

    def seed001(self) -> dict[str, object] | None:
        """With seed 001's positioning: P(seated) beside the pose reliability P(|dP| < d) of the
        same sampled robots, and the paper's (its own robot's) figures."""
        if self.config.positioning != "seed001" or not self.rows:
            return None
        err = np.array([r.sample.tool_error for r in self.rows])
        return {"p_seated": self.success_rate,
                "p_position_within_mm": {str(d): float((err < d * 1e-3).mean())
                                         for d in PAPER_POSITION_RELIABILITY},
                "paper_p_position_within_mm": {str(d): p for d, p in PAPER_POSITION_RELIABILITY.items()},
                "median_position_error_mm": float(np.median(err) * 1e3)}

    @property
    def wilson95(self) -> tuple[float, float]:
        n = len(self.rows)
        return wilson_interval(self.counts["success"], n) if n else (float("nan"), float("nan"))


def scene_config(cfg: MonteCarloConfig) -> TrialSceneConfig:
    """The episode's cell for a trial: its arm's dry joint friction (EpisodeConfig.arm_friction)."""
    friction = EpisodeConfig().arm_friction
    return TrialSceneConfig(arm_joint_friction=tuple(friction * f for f in PANDA_COULOMB_FRICTION))


def trial_config(cfg: MonteCarloConfig) -> TrialConfig:
    return TrialConfig(InsertionConfig(force_n=cfg.force_n, time_limit_s=cfg.time_limit_s))


def _tip_off_axis(start: TrialStart, scene: TrialSceneConfig) -> float:
    """The true tip's distance from the hole axis at the start [m] (the hole axis is vertical)."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, start.part_quat)
    tip = start.part_pos - scene.conductor.journal_length * rot.reshape(3, 3)[:, 2]
    return float(np.hypot(*(tip - np.asarray(scene.entry))[:2]))


def prepare(cfg: MonteCarloConfig, seed: int, trials: range, q_guess: np.ndarray,
            scene: TrialSceneConfig | None = None
            ) -> tuple[list, list[TrialStart], list[TrialSample]]:
    """Models, starts and samples of ``trials`` (one compile and one inverse kinematics each)."""
    scene = scene or scene_config(cfg)
    models, starts, samples = [], [], []
    for k in trials:
        sample = draw_trial(cfg, seed, k)
        model, start = _scene_and_start(cfg, sample.draw, scene, q_guess)
        models.append(model)
        starts.append(start)
        samples.append(sample)
    return models, starts, samples


def _scene_and_start(cfg: MonteCarloConfig, d: TrialDraw, scene: TrialSceneConfig, q_guess: np.ndarray
                     ) -> tuple[mujoco.MjModel, TrialStart]:
    model = build_trial_spec(scene, d.hole_diameter, d.journal_diameter, d.body_diameter).compile()
    start = plan_start(model, TrialIds.of(model), d, np.asarray(scene.entry),
                       scene.conductor.journal_length, q_guess, cfg.start_height_mm * 1e-3)
    return model, start


class _Trials(Sequence[Trial]):
    """Trials ``first..stop-1``, each drawn, built and placed when asked for (a slot taking it),
    so that a run holds only its slots' models; with ``ahead`` the next ones are already being
    built in worker processes (checks/build_ahead.py)."""

    def __init__(self, cfg: MonteCarloConfig, seed: int, first: int, stop: int,
                 scene: TrialSceneConfig | None = None,
                 ahead: BuildAhead[tuple[Trial, TrialSample]] | None = None) -> None:
        self.first, self.stop = first, stop
        self.scene = scene or scene_config(cfg)
        self._build: Callable[[int], tuple[Trial, TrialSample]] = (
            ahead.get if ahead is not None else partial(_build, cfg, seed, scene=self.scene))
        self.samples: dict[int, tuple[TrialSample, TrialStart]] = {}

    def __len__(self) -> int:
        return self.stop - self.first

    def __getitem__(self, i):  # type: ignore[no-untyped-def, override]
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        k = self.first + int(i)
        trial, sample = self._build(k)
        self.samples[k] = (sample, trial.start)
        return trial


def _build(cfg: MonteCarloConfig, seed: int, k: int, scene: TrialSceneConfig | None = None
           ) -> tuple[Trial, TrialSample]:
    sample = draw_trial(cfg, seed, k)
    return trial_from(cfg, sample.draw, seed, k, scene), sample


def trial_from(cfg: MonteCarloConfig, draw: TrialDraw, seed: int, k: int,
               scene: TrialSceneConfig | None = None) -> Trial:
    """The trial of ``draw`` with trial ``k``'s sensor noise (in ``scene``, default the
    budget's)."""
    # every trial's inverse kinematics from the same guess: the arm has one redundant joint,
    # so the elbow a solution lands on depends on where the search started
    model, start = _scene_and_start(cfg, draw, scene or scene_config(cfg), np.array(HOME_Q))
    return Trial(model, start, trial_seeds(seed, [k])[0], draw.hole_diameter)


def build_trial(cfg: MonteCarloConfig, seed: int, k: int, scene: TrialSceneConfig | None = None) -> Trial:
    """Trial ``k`` of seed ``seed``, exactly as a run builds it."""
    return _build(cfg, seed, k, scene)[0]


def run_block(cfg: MonteCarloConfig, seed: int, first: int, stop: int, threads: int = 1,
              slots: int = BATCH, on_row: Callable[[TrialRow], None] | None = None,
              on_period: Callable[[int], None] | None = None, scene: TrialSceneConfig | None = None,
              engine: Callable[[mujoco.MjModel, int], mujoco.batch.Batch] | None = None,
              build_workers: int = 1) -> list[TrialRow]:
    """Trials first..stop-1 in ``slots`` simulations at a time (a local run, or one Ray task);
    ``on_row`` as each ends; ``scene``/``engine`` for another plant (``--gpu``);
    ``build_workers`` > 1 builds the trials' scenes ahead in that many processes."""
    scene = scene or scene_config(cfg)
    rows: list[TrialRow] = []
    ahead = (BuildAhead(partial(_build, cfg, seed, scene=scene), first, stop, build_workers)
             if build_workers > 1 else None)
    with ahead or nullcontext():
        trials = _Trials(cfg, seed, first, stop, scene, ahead)

        def done(i: int, r: TrialResult) -> None:
            k = first + i
            sample, start = trials.samples.pop(k)
            rows.append(TrialRow(k, sample, _tip_off_axis(start, scene) * 1e3, r))
            if on_row is not None:
                on_row(rows[-1])

        run_trials(trials, scene.chamfer, trial_config(cfg), threads, on_period, slots, done,
                   engine=engine)
    return sorted(rows, key=lambda r: r.trial)


def _ray_block(_: None, cfg: MonteCarloConfig, seed: int, first: int, stop: int) -> list[TrialRow]:
    return run_block(cfg, seed, first, stop, slots=stop - first)


def run_montecarlo(cfg: MonteCarloConfig, trials: int, seed: int, threads: int = 2,
                   batch: int = BATCH, on_rows: Callable[[list[TrialRow]], None] | None = None,
                   on_period: Callable[[int], None] | None = None,
                   ray_address: str | None = None, scene: TrialSceneConfig | None = None,
                   engine: Callable[[mujoco.MjModel, int], mujoco.batch.Batch] | None = None,
                   build_workers: int = 1) -> MonteCarloResult:
    """``trials`` trials here, ``batch`` simulations at a time on ``threads`` threads, a trial
    starting as another ends; or as one Ray task per ``batch`` trials (``ray_address``).
    ``on_rows`` gets the rows as they finish. Ctrl-C keeps the trials that finished; a dead Ray
    task's trials are missing from the result, and the reason is in ``errors``. ``scene`` and
    ``engine``: another plant for a local run (``--gpu``: MuJoCo Warp, the scene at the origin);
    ``build_workers`` > 1: a local run's trial scenes built ahead in that many processes."""
    if engine is not None and ray_address is not None:
        raise ConfigError(GPU_OR_RAY)
    if trials < 1 or threads < 1 or batch < 1:
        raise ConfigError(f"trials {trials}, threads {threads}, batch {batch}: each must be >= 1")
    t0 = time.perf_counter()
    result = MonteCarloResult(cfg, seed, trials)

    def keep(rows: list[TrialRow]) -> None:
        result.rows.extend(rows)
        if on_rows is not None:
            on_rows(rows)

    try:
        if ray_address is None:
            run_block(cfg, seed, 0, trials, threads, batch, lambda row: keep([row]), on_period,
                      scene, engine, build_workers)
        else:
            blocks = [(first, min(first + batch, trials)) for first in range(0, trials, batch)]
            for rows in _ray_rows(cfg, seed, blocks, ray_address, result):
                keep(rows)
    except KeyboardInterrupt:
        result.interrupted = True
    result.rows.sort(key=lambda r: r.trial)
    result.wall_s = time.perf_counter() - t0
    return result


def _ray_rows(cfg: MonteCarloConfig, seed: int, blocks: list[tuple[int, int]], address: str,
              result: MonteCarloResult) -> Iterator[list[TrialRow]]:
    args = [(cfg, seed, a, b) for a, b in blocks]
    for i, rows, exc in ray_map(_ray_block, args, address):
        if exc is not None:
            a, b = blocks[i]
            result.errors.append(f"trials {a}-{b - 1}: {type(exc).__name__}: "
                                 f"{(str(exc).strip().splitlines() or [''])[0]}")
            continue
        yield rows


def write_parquet(result: MonteCarloResult, path: Path) -> None:
    rows = [r.as_dict() for r in result.rows]
    table = pa.Table.from_pylist(rows)
    pq.write_table(table, path)


def sensitivity(result: MonteCarloResult) -> dict[str, float | None]:
    """Per error source, how well its size alone tells failed trials from seated ones: the
    probability that a failed trial's draw of it is larger than a seated one's (AUC; 0.5 = no
    bearing on the outcome, 1 = the failures are exactly the large draws, 0 = the small ones).
    None without both, or for a source this budget leaves out."""
    ok = np.array([r.result.outcome is Outcome.SUCCESS for r in result.rows])
    out: dict[str, float | None] = {}
    for src in SOURCES:
        size = np.array([r.sample.magnitude[src] for r in result.rows])
        if ok.all() or not ok.any() or np.ptp(size) == 0:
            out[src] = None
            continue
        fail, good = size[~ok], size[ok]
        greater = (fail[:, None] > good[None, :]).mean() + 0.5 * (fail[:, None] == good[None, :]).mean()
        out[src] = float(greater)
    return out
