"""Failed trials of a ``serpar montecarlo`` run, re-run one by one into rerun files for
``serpar replay`` (tasks/trial_recording.py): a trial is rebuilt from (seed, trial) alone, so
the file shows the very insertion the run scored, and says so when the re-run ends otherwise."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from serpar.checks.montecarlo import (
    MonteCarloResult,
    TrialRow,
    build_trial,
    scene_config,
    trial_config,
)
from serpar.tasks.trial_recording import record_trial

FOLDER = "failed"
"""Where under --out DIR the recordings go: DIR/failed/trial_<k>.rrd."""


def failed_rows(result: MonteCarloResult) -> list[TrialRow]:
    return [r for r in result.rows if r.result.outcome.value != "success"]


def record_failed(result: MonteCarloResult, out: Path, limit: int) -> Iterator[dict[str, object]]:
    """The first ``limit`` failed trials (by trial number) recorded into ``out/failed/``, one
    by one: per trial its number, file, outcome in the run and in the re-run."""
    folder = out / FOLDER
    scene, cfg = scene_config(result.config), trial_config(result.config)
    for row in failed_rows(result)[:limit]:
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"trial_{row.trial}.rrd"
        ran = row.result.outcome.value
        name = f"montecarlo seed {result.seed} trial {row.trial} ({ran})"
        again = record_trial(build_trial(result.config, result.seed, row.trial), scene.chamfer, cfg,
                             path, name, expected=ran)
        yield {"trial": row.trial, "file": str(path), "outcome": ran, "rerun_outcome": again.outcome.value}
