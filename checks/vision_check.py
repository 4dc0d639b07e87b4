"""`serpar vision-check`: calibrate both stereo pairs from rendered board images, then run the
vision of steps 1, 2 and 4 on rendered scenes and score every result against the simulator's
truth — at each requested readout size, with per-step timings.

Only the scoring reads simulator state; every measurement goes through vision/ on pixels and
the calibrated cameras.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from serpar.calibration.camera_calibration import CalibrationRun, calibrate
from serpar.checks.vision_inhand_scenes import (
    measured_tcp,
    pose_inspect_with_error,
    random_grasp_error,
    true_in_hand,
)
from serpar.checks.vision_scenes import hole_errors, make_scene, random_offset, tray_match
from serpar.errors import ConfigError
from serpar.sim.render import save_png
from serpar.sim.scene import SceneConfig, build_scene
from serpar.vision.camera import StereoPair
from serpar.vision.errors import VisionError
from serpar.vision.imaging import Camera, ImagingConfig
from serpar.vision.inhand import inspect_in_hand
from serpar.vision.inhand_overlay import draw_in_hand
from serpar.vision.layout import plate_layout, tray_region
from serpar.vision.overlay import draw_conductors, draw_plate
from serpar.vision.plate import locate_holes
from serpar.vision.tray_conductors import locate_conductors

TOP, INSPECT = ("top_left", "top_right"), ("inspect_left", "inspect_right")


@dataclass(frozen=True)
class VisionCheckConfig:
    widths: tuple[int, ...] = (2048, 1024)
    platform_poses: int = 10
    """Random platform poses for step 2 (and step 1, on the same frames)."""
    occupied: int = 6
    """Conductors seated in random holes in each step-2 scene."""
    inhand_trials: int = 10
    seed: int = 0
    noise: bool = True
    overlay_dir: Path | None = None

    def __post_init__(self) -> None:
        if not self.widths or any(w not in (2048, 1024, 512) for w in self.widths):
            raise ConfigError(f"widths {self.widths}: choose from 2048 (full), 1024 (reduced), 512")
        if self.platform_poses < 1 or self.inhand_trials < 1 or not 0 <= self.occupied <= 30:
            raise ConfigError("platform_poses >= 1, inhand_trials >= 1, occupied in 0..30")

    def imaging(self, width: int) -> ImagingConfig:
        return ImagingConfig(width=width) if self.noise else ImagingConfig.ideal(width)


def _stats(values: list[float] | np.ndarray, scale: float = 1.0) -> dict[str, float]:
    """mean / p95 / max / n of `values` times `scale` (1e3: metres to millimetres)."""
    e = scale * np.asarray(values, float)
    if e.size == 0:
        return {"mean": float("nan"), "p95": float("nan"), "max": float("nan"), "n": 0}
    return {"mean": float(e.mean()), "p95": float(np.percentile(e, 95)), "max": float(e.max()), "n": int(e.size)}


def _calibration_summary(run: CalibrationRun) -> dict[str, object]:
    c = run.calibration
    return {"rms_px": c.rms_px, "rectified_row_error_px": c.rectified_row_error_px, "views": c.views_used,
            "score": run.score, "seconds": run.seconds}


def _overlay(cfg: VisionCheckConfig, name: str, image: np.ndarray) -> None:
    if cfg.overlay_dir is not None:
        save_png(image, Path(cfg.overlay_dir) / name)


def _steps_1_2(cfg: VisionCheckConfig, pair: StereoPair, imaging: ImagingConfig, rng: np.random.Generator,
               tick: Callable[[], None]) -> dict[str, object]:
    scene_cfg = SceneConfig(seed=cfg.seed)
    hole_err, axis_err, raw_err, tray_err = [], [], [], []
    correct = total = missed = false_pos = 0
    failures: list[str] = []
    t_step1 = t_step2 = 0.0
    layout, region = plate_layout(scene_cfg), tray_region(scene_cfg)
    for k in range(cfg.platform_poses):
        offset = random_offset(scene_cfg, rng)
        conductors = rng.choice(scene_cfg.n_conductors, cfg.occupied, replace=False)
        holes = rng.choice(scene_cfg.baseplate.n_holes, cfg.occupied, replace=False)
        scene = make_scene(scene_cfg, offset, dict(zip(conductors.tolist(), holes.tolist())))
        camera = Camera(scene.model, imaging, seed=int(rng.integers(1 << 31)))
        frames = camera.shoot(scene.data, TOP)
        camera.close()
        left, right = frames[TOP[0]], frames[TOP[1]]
        t0 = time.perf_counter()
        try:
            sightings = locate_conductors(pair, left, right, region, scene_cfg.conductor)
            t1 = time.perf_counter()
            plate = locate_holes(pair, left, right, scene_cfg.baseplate, scene_cfg.conductor, layout)
            t2 = time.perf_counter()
        except VisionError as exc:  # a typed failure is a result: count it, keep the frame, go on
            failures.append(f"pose {k}: {type(exc).__name__}: {exc}")
            total += scene_cfg.baseplate.n_holes
            _overlay(cfg, f"{imaging.width}/failed_pose{k}_left.png", left)
            _overlay(cfg, f"{imaging.width}/failed_pose{k}_right.png", right)
            tick()
            continue
        t_step1, t_step2 = t_step1 + t1 - t0, t_step2 + t2 - t1
        errors = hole_errors(scene, plate)
        total += len(plate.holes)
        correct += int(errors.status_right.sum())
        hole_err += errors.centre.tolist()
        axis_err += [errors.axis_deg] * len(errors.centre)
        raw_err += errors.raw.tolist()
        in_tray = sorted(set(range(scene_cfg.n_conductors)) - set(conductors.tolist()))
        found, n_missed, n_false = tray_match(scene, sightings, in_tray)
        tray_err += found.tolist()
        missed, false_pos = missed + n_missed, false_pos + n_false
        if k == 0:
            _overlay(cfg, f"{imaging.width}/step2_plate_left.png", draw_plate(left, plate, pair.left))
            _overlay(cfg, f"{imaging.width}/step1_tray_left.png", draw_conductors(left, sightings, pair.left))
        tick()
    n = cfg.platform_poses
    return {
        "step1_tray": {"error_mm": _stats(tray_err, 1e3), "missed": missed, "false_detections": false_pos,
                       "seconds_per_frame_pair": t_step1 / n},
        "step2_holes": {"centre_error_mm": _stats(hole_err, 1e3), "axis_error_deg": _stats(axis_err),
                        "raw_triangulated_error_mm": _stats(raw_err, 1e3),
                        "occupancy_accuracy": correct / max(1, len(hole_err)),
                        "holes_seen": len(hole_err), "holes_total": total, "platform_poses": n,
                        "failures": failures,
                        "seconds_per_frame_pair": t_step2 / n},
    }


def _step_4(cfg: VisionCheckConfig, pair: StereoPair, imaging: ImagingConfig, rng: np.random.Generator,
            tick: Callable[[], None]) -> dict[str, object]:
    scene = build_scene(SceneConfig(seed=cfg.seed, n_conductors=1))
    offset_err, tilt_err, tip_err, seconds = [], [], [], 0.0
    failures: list[str] = []
    camera = Camera(scene.model, imaging, seed=int(rng.integers(1 << 31)))
    for k in range(cfg.inhand_trials):
        pose_inspect_with_error(scene, random_grasp_error(rng))
        frames = camera.shoot(scene.data, INSPECT)
        tcp_pos, tcp_rot = measured_tcp(scene)
        t0 = time.perf_counter()
        try:
            m = inspect_in_hand(pair, frames[INSPECT[0]], frames[INSPECT[1]], tcp_pos, tcp_rot,
                                scene.config.conductor)
        except VisionError as exc:
            failures.append(f"grasp {k}: {type(exc).__name__}: {exc}")
            tick()
            continue
        seconds += time.perf_counter() - t0
        truth = true_in_hand(scene)
        offset_err.append(float(np.linalg.norm(m.offset - truth.tip[:2])))
        tilt_err.append(float(np.arccos(np.clip(m.axis @ truth.axis, -1, 1))))
        tip_err.append(abs(m.tip_z - truth.tip[2]))
        if k == 0:
            _overlay(cfg, f"{imaging.width}/step4_inhand_left.png", draw_in_hand(frames[INSPECT[0]], m, pair.left))
        tick()
    camera.close()
    return {"offset_error_mm": _stats(offset_err, 1e3), "tip_error_mm": _stats(tip_err, 1e3),
            "tilt_error_deg": _stats(np.degrees(tilt_err)),
            "trials": cfg.inhand_trials, "failures": failures,
            "seconds_per_inspection": seconds / max(1, len(offset_err))}


def run_vision_check(cfg: VisionCheckConfig = VisionCheckConfig(),
                     tick: Callable[[], None] = lambda: None) -> dict[str, object]:
    """Everything `serpar vision-check` prints, keyed by readout width."""
    out: dict[str, object] = {"config": {"widths": list(cfg.widths), "platform_poses": cfg.platform_poses,
                                         "occupied": cfg.occupied, "inhand_trials": cfg.inhand_trials,
                                         "seed": cfg.seed, "noise": cfg.noise}}
    for width in cfg.widths:
        imaging = cfg.imaging(width)
        rng = np.random.default_rng(cfg.seed)
        def overlay(name: str, image: np.ndarray, width: int = width) -> None:
            _overlay(cfg, f"{width}/{name}", image)

        top = calibrate("top", imaging, cfg.seed, overlay=overlay)
        tick()
        inspect = calibrate("inspect", imaging, cfg.seed, overlay=overlay)
        tick()
        result = {"calibration": {"top": _calibration_summary(top), "inspect": _calibration_summary(inspect)}}
        result.update(_steps_1_2(cfg, top.calibration.pair, imaging, rng, tick))
        result["step4_inhand"] = _step_4(cfg, inspect.calibration.pair, imaging, rng, tick)
        out[str(width)] = result
    return out


def total_ticks(cfg: VisionCheckConfig) -> int:
    return len(cfg.widths) * (2 + cfg.platform_poses + cfg.inhand_trials)
