"""`serpar bench --episode`: wall time of the assembly task (issue 5).

One hole cycle's wall and simulated time (from a short episode's records), the 36-hole
episode estimated from it (set-up + 36 cycles: a lower bound, since the parts already seated
wake with the moving platform and make later cycles dearer; time a real one with `serpar
run`), and the speed-up of 2 worker processes over 1 on the same episodes.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.tasks.episode_config import N_HOLES, EpisodeConfig
from serpar.tasks.run_episodes import Record, episode_configs, run_many


def _holes(records: list[Record]) -> list[Record]:
    return [r for r in records if r["kind"] == "hole"]


def episode_bench(holes: int = 2, tick: Callable[[str], None] = lambda name: None) -> dict[str, object]:
    cfg = EpisodeConfig(holes=holes)
    calibrated_pairs(cfg.camera_width)  # cached calibration is not part of the timings
    t0 = time.perf_counter()
    records = run_many([cfg])
    wall = time.perf_counter() - t0
    tick("episode")
    cycles = _holes(records)
    cycle_wall = statistics.fmean(float(r["wall_s"]) for r in cycles)
    cycle_sim = statistics.fmean(float(r["cycle_time_s"]) for r in cycles)
    setup = wall - sum(float(r["wall_s"]) for r in cycles)
    speed: dict[str, float] = {}
    for workers in (1, 2):
        t0 = time.perf_counter()
        run_many(episode_configs(EpisodeConfig(holes=1), 2, first_seed=10), workers)
        speed[f"workers_{workers}_s"] = time.perf_counter() - t0
        tick(f"workers_{workers}")
    return {
        "hole_cycle": {"wall_s": cycle_wall, "sim_s": cycle_sim, "realtime_factor": cycle_sim / cycle_wall,
                       "holes_timed": len(cycles), "outcomes": [r["outcome"] for r in cycles]},
        "episode_setup_wall_s": setup,
        "episode_36_holes_estimated_wall_s": setup + N_HOLES * cycle_wall,
        "two_episodes_of_one_hole": {**speed, "speedup": speed["workers_1_s"] / speed["workers_2_s"]},
    }
