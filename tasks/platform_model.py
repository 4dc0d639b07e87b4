"""Which model of itself the platform uses for the step-5 correction
(:attr:`serpar.tasks.episode_config.EpisodeConfig.stewart_calibration`): the nominal geometry, a file of
identified parameters, or the parameters identified by a simulated motion-capture campaign in
the episode's own cell (:mod:`serpar.calibration.stewart_campaign`), run once and cached on disk like the
camera calibration.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from serpar.calibration.camera_cache import Log, Stage, cache_dir, stage_of
from serpar.calibration.stewart_campaign import N_POSES, MocapNoise, calibrate
from serpar.calibration.stewart_params import load_stewart_parameters, save_stewart_parameters
from serpar.tasks.episode_config import EpisodeConfig, scene_config

CALIBRATION_VERSION = 5
"""Bump when the Stewart campaign, solver or the simulated cell changes (invalidates cached
parameter files). 2: wedge bores (lighter plate) and the commander starting from its model's
reading of the legs in force. 3: the still platform sleeps (settles to 0.05 um first). 4: each
pose held until the legs settle (SettleCriterion), not a fixed 0.4 s. 5: the arm holds at the
transit step while the platform sleeps (sim/transit_step.py)."""

def campaign_file(cfg: EpisodeConfig, log: Log | None = None, stage: Stage | None = None) -> Path:
    """Identified parameters of the episode's platform (its hidden errors), from a simulated
    motion-capture campaign with the default noise; computed on the first call (announced to
    `log` or run inside `stage`, the caller's progress), then cached."""
    hidden = cfg.hidden_errors.draw(cfg.seed)
    noise = MocapNoise()
    key = hashlib.sha256(json.dumps([CALIBRATION_VERSION, hidden.round(12).tolist(), N_POSES,
                                     dataclasses.asdict(noise)]).encode()).hexdigest()[:16]
    path = cache_dir() / f"stewart_parameters_{key}.json"
    if not path.exists():
        text = (f"calibrating the Stewart platform ({N_POSES} poses, mocap noise "
                f"{noise.position_m * 1e3:g} mm / {noise.angle_deg:g} deg; cached in {path.parent})")
        with stage_of(text, log, stage):
            result = calibrate(scene_config(cfg), N_POSES, noise, seed=cfg.seed)
        save_stewart_parameters(path, result.errors, {"residual_rms_m": result.residual_rms_m,
                                                      "poses": N_POSES, "noise": dataclasses.asdict(noise)})
    return path


def believed_errors(cfg: EpisodeConfig, log: Log | None = None, stage: Stage | None = None) -> np.ndarray | None:
    """(6, 7) joint errors the step-5 model assumes [m]; None = the nominal model."""
    if not cfg.stewart_correction or cfg.stewart_calibration == "none":
        return None
    if cfg.calibration_file is not None:
        return load_stewart_parameters(cfg.calibration_file)
    return load_stewart_parameters(campaign_file(cfg, log, stage))


def prepare_models(configs: Iterable[EpisodeConfig], log: Log | None = None,
                   stage: Stage | None = None) -> None:
    """Check every named parameters file and run each needed campaign once, here: before any
    episode starts, so a bad file fails at once and parallel workers find the cache filled;
    `stage` shows a campaign's progress (see :data:`serpar.calibration.camera_cache.Stage`)."""
    for cfg in configs:
        believed_errors(cfg, log, stage)
