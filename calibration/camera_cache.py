"""Calibrated stereo pairs for the task, calibrated once per cell layout and cached on disk.

A real cell calibrates its cameras once and reuses the result for every episode; so does
serpar. The key is everything the calibration depends on (the pairs' layout, the image
width, the calibration seed and the campaign's version), so a changed layout recalibrates.
The cache is a folder of JSON files ($SERPAR_CACHE, default ~/.cache/serpar), written
atomically so parallel workers can share it.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

from serpar.calibration.camera_calibration import DEFAULT_CELL, calibrate
from serpar.sim.scene import SceneConfig
from serpar.vision.camera import CameraModel, StereoPair
from serpar.vision.imaging import ImagingConfig

CAMPAIGN_VERSION = 1
"""Bump when the calibration campaign or solver changes (invalidates every cached file)."""
PAIRS = ("top", "inspect")

Log = Callable[[str], None]
Stage = Callable[[str], AbstractContextManager[object]]
"""Progress of a long step (a calibration): ``with stage(text):`` runs around it; the command
line shows the elapsed time (serpar.cli.output.stage). Library code prints nothing itself."""


def stage_of(text: str, log: Log | None = None, stage: Stage | None = None) -> AbstractContextManager[object]:
    """The context a long step runs in: `stage`'s, else `log` told that it starts, else none."""
    if stage is not None:
        return stage(text)
    if log is not None:
        log(text)
    return contextlib.nullcontext()


def cache_dir() -> Path:
    return Path(os.environ.get("SERPAR_CACHE", Path.home() / ".cache" / "serpar"))


def _key(cfg: SceneConfig, name: str, width: int, seed: int) -> str:
    layout = [dataclasses.asdict(p) for p in cfg.stereo_pairs if p.name == name]
    text = json.dumps([CAMPAIGN_VERSION, name, width, seed, layout], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _write_atomic(path: Path, payload: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        json.dump(payload, f)
    os.replace(tmp, path)


def calibrated_pair(name: str, width: int, cfg: SceneConfig = DEFAULT_CELL, seed: int = 0,
                    log: Log | None = None, stage: Stage | None = None) -> StereoPair:
    """The pair `name` calibrated from rendered board views at `width`, from the cache if there;
    a calibration that runs is announced to `log` or runs inside `stage` (progress)."""
    path = cache_dir() / f"calibration_{name}_{width}_{_key(cfg, name, width, seed)}.json"
    if path.exists():
        try:
            d = json.loads(path.read_text())
            return StereoPair(CameraModel.from_dict(d["left"]), CameraModel.from_dict(d["right"]))
        except (OSError, ValueError, KeyError):
            pass  # unreadable cache entry: calibrate again and overwrite it
    text = f"calibrating the {name} stereo pair at {width} px (once per layout; cached in {path.parent})"
    with stage_of(text, log, stage):
        run = calibrate(name, ImagingConfig(width=width), seed=seed, scene_config=cfg)
    pair = run.calibration.pair
    _write_atomic(path, {"left": pair.left.as_dict(), "right": pair.right.as_dict(),
                         "score": run.score, "views": run.views})
    return pair


def calibrated_pairs(width: int, cfg: SceneConfig = DEFAULT_CELL, seed: int = 0,
                     log: Log | None = None, stage: Stage | None = None) -> dict[str, StereoPair]:
    return {name: calibrated_pair(name, width, cfg, seed, log, stage) for name in PAIRS}
