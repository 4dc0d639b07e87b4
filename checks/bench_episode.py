"""`serpar bench --episode`: wall time of the assembly task (issue 5).

One hole cycle's wall and simulated time (from a short episode's records), the 36-hole
episode estimated from it (set-up + 36 cycles: a lower bound, since the parts already seated
wake with the moving platform and make later cycles dearer; time a real one with `serpar
run`), and the speed-up of 2 worker processes over 1 on two copies of one episode (equal
work, so the figure is the pool's efficiency, not the longer episode's share).
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.tasks.episode_config import N_HOLES, EpisodeConfig
from serpar.tasks.run_episodes import Record, run_many


def _holes(records: list[Record]) -> list[Record]:
    return [r for r in records if r["kind"] == "hole"]


def episode_bench(holes: int = 2, tick: Callable[[str], None] = lambda name: None,
                  bare_steps_per_s: float | None = None) -> dict[str, object]:
    """``bare_steps_per_s``: bare ``mj_step`` of the cell (``serpar bench``'s floor), for the
    check of the cycle's physics time against its step count."""
    cfg = EpisodeConfig(holes=holes)
    calibrated_pairs(cfg.camera_width)  # cached calibration is not part of the timings
    t0 = time.perf_counter()
    records = run_many([cfg])
    wall = time.perf_counter() - t0
    tick("episode")
    cycles = _holes(records)
    cycle_wall = statistics.fmean(float(r["wall_s"]) for r in cycles)
    cycle_sim = statistics.fmean(float(r["cycle_time_s"]) for r in cycles)
    physics = statistics.fmean(float(r["physics_wall_s"]) for r in cycles)
    steps = statistics.fmean(float(r["physics_steps"]) for r in cycles)
    setup = wall - sum(float(r["wall_s"]) for r in cycles)
    speed: dict[str, float] = {}
    for workers in (1, 2):
        t0 = time.perf_counter()
        run_many([EpisodeConfig(holes=1, seed=10)] * 2, workers)  # equal work: the speed-up is the pool's
        speed[f"workers_{workers}_s"] = time.perf_counter() - t0
        tick(f"workers_{workers}")
    return {
        "hole_cycle": {"wall_s": cycle_wall, "sim_s": cycle_sim, "realtime_factor": cycle_sim / cycle_wall,
                       "physics_wall_s": physics, "physics_steps": steps,
                       "wall_over_physics": cycle_wall / physics if physics > 0 else float("nan"),
                       # a check of the step timer: the steps at the bench's bare rate
                       "steps_at_bare_rate_s": (steps / bare_steps_per_s if bare_steps_per_s
                                                else float("nan")),
                       "holes_timed": len(cycles), "outcomes": [r["outcome"] for r in cycles]},
        "episode_setup_wall_s": setup,
        "episode_36_holes_estimated_wall_s": setup + N_HOLES * cycle_wall,
        "two_episodes_of_one_hole": {**speed, "speedup": speed["workers_1_s"] / speed["workers_2_s"]},
    }


GOALS: dict[str, tuple[str, float, str]] = {
    "hole_cycle_realtime_factor": ("hole cycle, x real time", 2.0, ">="),
    "hole_cycle_wall_over_physics": ("hole cycle wall / its mj_step time", 1.3, "<="),
    "episode_36_holes_estimated_wall_s": ("36-hole episode, estimated [s]", 180.0, "<="),
    "loop_over_bare_free_motion": ("control loop / bare mj_step, free motion", 1.15, "<="),
    "loop_over_bare_in_contact": ("control loop / bare mj_step, in contact", 1.15, "<="),
    "speedup_2_workers": ("2 workers vs 1", 1.9, ">="),
    "diagnosis_60s_mix_s": ("arm-dynamics diagnosis, 60-s mix twin, full library [s]", 120.0,
                            "<="),
}
"""The bench's targets, each figure's name -> (label, goal, sense)."""


def against_goals(report: dict[str, object]) -> dict[str, dict[str, object]]:
    """Each measured figure of the bench beside its goal: {name: {label, value, goal, met}}."""
    episode = report.get("episode")
    values: dict[str, float] = {
        "loop_over_bare_free_motion": report["free_motion"]["overhead"],  # type: ignore[index]
        "loop_over_bare_in_contact": report["in_contact"]["overhead"],  # type: ignore[index]
    }
    if isinstance(episode, dict):
        values["hole_cycle_realtime_factor"] = episode["hole_cycle"]["realtime_factor"]
        values["hole_cycle_wall_over_physics"] = episode["hole_cycle"]["wall_over_physics"]
        values["episode_36_holes_estimated_wall_s"] = episode["episode_36_holes_estimated_wall_s"]
        values["speedup_2_workers"] = episode["two_episodes_of_one_hole"]["speedup"]
    diagnosis = report.get("diagnose")
    if isinstance(diagnosis, dict):
        values["diagnosis_60s_mix_s"] = diagnosis["diagnosis_s"]
    out = {}
    for name, (label, goal, sense) in GOALS.items():
        if name in values:
            v = float(values[name])
            out[name] = {"label": label, "value": v, "goal": f"{sense} {goal:g}",
                         "met": v >= goal if sense == ">=" else v <= goal}
    return out
