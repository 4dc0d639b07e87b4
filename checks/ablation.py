"""The paper's argument as one table (issue 5): success rate per configuration of the cell.

Arms: the serial robot alone; with the Stewart step-5 correction through the platform's
nominal (uncalibrated) model; through the model calibrated by a simulated motion-capture
campaign (:mod:`serpar.calibration.stewart_campaign`); and the calibrated cell with impedance instead of
direct force-position control. Every arm runs the same episode seeds, so the arms differ only
in the configuration.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from serpar.errors import ConfigError
from serpar.tasks.episode_config import N_HOLES, EpisodeConfig
from serpar.tasks.run_episodes import Record, RunSummary, episode_configs, run_many, summarise


@dataclass(frozen=True)
class AblationArm:
    name: str
    config: EpisodeConfig


def spread_holes(count: int) -> tuple[int, ...]:
    """`count` holes spread evenly over the grid's index range, first and last included (for 6:
    0, 7, 14, 21, 28, 35, the 6 x 6 grid's diagonal). The platform's model errors grow with the
    distance it moves the plate from home, so a row next to the station hides what the
    calibration is for."""
    if not 1 <= count <= N_HOLES:
        raise ConfigError(f"--holes {count}: a count in 1..{N_HOLES}")
    return tuple(int(h) for h in np.unique(np.linspace(0, N_HOLES - 1, count).round()))


def ablation_arms(base: EpisodeConfig) -> list[AblationArm]:
    stewart = dataclasses.replace(base, stewart_correction=True, stewart_calibration="none",
                                  controller="force_position")
    calibrated = dataclasses.replace(stewart, stewart_calibration="campaign")
    return [
        AblationArm("serial robot alone", dataclasses.replace(stewart, stewart_correction=False)),
        AblationArm("Stewart, uncalibrated model", stewart),
        AblationArm("Stewart, calibrated model", calibrated),
        AblationArm("calibrated, impedance control", dataclasses.replace(calibrated, controller="impedance")),
    ]


@dataclass(frozen=True)
class ArmResult:
    name: str
    summary: RunSummary
    misalignment_mm: float
    """Mean lateral misalignment at first contact over the holes that touched [mm]."""

    def as_dict(self) -> dict[str, object]:
        return {"kind": "ablation_arm", "config": self.name, "misalignment_mm": self.misalignment_mm,
                **{k: v for k, v in self.summary.as_dict().items() if k != "kind"}}


def run_ablation(arms: Sequence[AblationArm], episodes: int, workers: int = 1,
                 on_records: Callable[[list[Record]], None] | None = None,
                 on_hole: Callable[[Record], None] | None = None,
                 ray_address: str | None = None) -> tuple[list[ArmResult], list[Record]]:
    configs, labels = [], []
    for arm in arms:
        for cfg in episode_configs(arm.config, episodes):
            configs.append(cfg)
            labels.append(arm.name)
    records = run_many(configs, workers, on_records, on_hole, labels, ray_address=ray_address)
    results = []
    for arm in arms:
        mine = [r for r in records if r.get("config") == arm.name]
        touched = [float(r["lateral_misalignment_mm"]) for r in mine
                   if r["kind"] == "hole" and not math.isnan(float(r["lateral_misalignment_mm"]))]
        results.append(ArmResult(arm.name, summarise(mine), statistics.fmean(touched) if touched else float("nan")))
    return results, records
