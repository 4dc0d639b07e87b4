"""What `serpar montecarlo` samples per insertion trial, and the draws themselves.

Every error source is its own field, so the failures can be laid at a source's door. The
defaults are the cell's own measured errors (docs/vision.md, docs/calibration.md): a user's
DIST.yaml replaces any of them (``serpar montecarlo --config DIST.yaml``; keys are the field
names below). Lateral errors are isotropic normals with the stated sigma per axis; angles are
in degrees, lengths in millimetres, as a cell engineer writes an error budget.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from serpar.checks.error_analysis import arm_model, perturbed_poses, transmission_errors
from serpar.checks.tool_changer_robot import ErrorSample, sample_transmission
from serpar.errors import ConfigError
from serpar.sim.tolerances import BODY_H6, DISTRIBUTIONS, HOLE_H7, JOURNAL_H6
from serpar.tasks.trial_start import TrialDraw

SOURCES: tuple[str, ...] = ("clearance", "hole_vision", "hole_tilt", "platform", "inhand_tip",
                            "inhand_tilt", "grasp_offset", "grasp_tilt", "tool_position", "tool_tilt")
"""The error sources a trial's draw is made of (the sensitivity table's rows)."""
POSITIONING: tuple[str, ...] = ("vision", "seed001")
"""Where the journal is brought to the hole from: 'vision' (the cell: steps 2 and 4 measure,
the platform aligns; the error budget's fields) or 'seed001' (seed 001's error analysis: the
Panda's joint and link errors of its Table 1, mapped through the arm's kinematics to the tool
tip, no vision; the clearance and grasp errors stay)."""


@dataclass(frozen=True)
class MonteCarloConfig:
    """One error budget; every sigma is per lateral axis (a 2-D isotropic normal)."""

    positioning: str = "vision"
    """'vision' or 'seed001' (:data:`POSITIONING`)."""
    tolerance_distribution: str = "uniform"
    """Hole (H7), journal and body (h6) diameters within their bands: 'uniform' or 'normal'
    (3 sigma at the band edges, clipped)."""
    hole_vision_sigma_mm: float = 0.014
    """Step 2's error of a hole centre (measured: mean 0.018, p95 0.032 mm at 2048 x 1536,
    `serpar vision-check`; a 2-D normal with 0.014 mm per axis has mean 0.0175, p95 0.034)."""
    hole_tilt_sigma_deg: float = 0.0136
    """Step 2's error of the hole axis (measured mean 0.017 deg)."""
    platform_sigma_mm: float = 0.001
    """Where the calibrated Stewart platform puts the hole against its command (calibration
    residual <= 0.76 um, `serpar calibrate stewart`; the follow dead band 2 um)."""
    inhand_tip_sigma_mm: float = 0.0019
    """Step 4's error of the journal tip in the grip (measured mean 0.0024 mm)."""
    inhand_tilt_sigma_deg: float = 0.0128
    """Step 4's error of the journal axis (measured mean 0.016 deg)."""
    grasp_offset_sigma_mm: float = 0.1
    """The part off the pads' centre along the pads (the pick from its tray pocket)."""
    grasp_tilt_sigma_deg: float = 0.3
    """The part's lean in the pads' plane."""
    start_height_mm: float = 2.5
    """Measured tip above the believed hole entry at the start: the hover, where the episode's
    insertion starts (the platform then follows the TCP down to 0.3 mm above the entry)."""
    time_limit_s: float = 3.0
    """Simulated time a trial may take from its start; beyond it the trial is a timeout."""
    force_n: float = 5.0
    """The push F_d along the hole axis [N] (the episode's)."""

    def __post_init__(self) -> None:
        if self.positioning not in POSITIONING:
            raise ConfigError(f"positioning {self.positioning!r}; valid: {', '.join(POSITIONING)}")
        if self.tolerance_distribution not in DISTRIBUTIONS:
            raise ConfigError(f"tolerance_distribution {self.tolerance_distribution!r}; valid: "
                              f"{', '.join(DISTRIBUTIONS)}")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name.endswith(("_sigma_mm", "_sigma_deg")) and not 0 <= value <= (1.0 if f.name.endswith("mm") else 5.0):
                unit = "mm" if f.name.endswith("mm") else "deg"
                raise ConfigError(f"{f.name} {value}: valid 0..{1.0 if unit == 'mm' else 5.0} {unit}")
        if not 0.05 <= self.start_height_mm <= 5.0:
            raise ConfigError(f"start_height_mm {self.start_height_mm}: valid 0.05..5 mm")
        if not 0.3 <= self.time_limit_s <= 30.0:
            raise ConfigError(f"time_limit_s {self.time_limit_s}: valid 0.3..30 s")
        if not 1.0 <= self.force_n <= 15.0:
            raise ConfigError(f"force_n {self.force_n}: valid 1..15 N")


@dataclass(frozen=True)
class TrialSample:
    """One trial's draw and each source's share of the lateral error at the start [m]."""

    draw: TrialDraw
    magnitude: dict[str, float]
    """Each source's size in this trial, by :data:`SOURCES`: a lateral error's length [m], a
    tilt's angle [rad], the diametral clearance [m]."""
    tilt: float
    """Angle between the journal and hole axes at the start [rad]."""
    tool_error: float = float("nan")
    """'seed001' positioning: |dP| of the tool tip [m] (seed 001's reliability is P(|dP| < d))."""


def _normal2(rng: np.random.Generator, sigma: float) -> tuple[float, float]:
    x, y = rng.normal(0.0, sigma, 2)
    return float(x), float(y)


def draw_trial(cfg: MonteCarloConfig, seed: int, trial: int) -> TrialSample:
    """Trial ``trial``'s draw: its own stream from (seed, trial), whatever batch it runs in."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, trial]))
    dist = cfg.tolerance_distribution
    hole = float(HOLE_H7.draw(rng, 1, dist)[0])  # type: ignore[arg-type]
    journal = float(JOURNAL_H6.draw(rng, 1, dist)[0])  # type: ignore[arg-type]
    body = float(BODY_H6.draw(rng, 1, dist)[0])  # type: ignore[arg-type]
    hole_vision = np.array(_normal2(rng, cfg.hole_vision_sigma_mm * 1e-3))
    platform = np.array(_normal2(rng, cfg.platform_sigma_mm * 1e-3))
    hole_tilt = np.radians(np.array(_normal2(rng, cfg.hole_tilt_sigma_deg)))
    tip = _normal2(rng, cfg.inhand_tip_sigma_mm * 1e-3)
    tilt = np.radians(np.array(_normal2(rng, cfg.inhand_tilt_sigma_deg)))
    grasp_offset = float(rng.normal(0.0, cfg.grasp_offset_sigma_mm * 1e-3))
    grasp_tilt = float(np.radians(rng.normal(0.0, cfg.grasp_tilt_sigma_deg)))
    if cfg.positioning == "seed001":
        return _seed001(rng, hole, journal, body, grasp_offset, grasp_tilt)
    # The hole's axis error tilts the hole; with the plate held level it is the journal's
    # axis error relative to the hole's, as the in-hand one is.
    vision_tilt = (float(tilt[0] + hole_tilt[0]), float(tilt[1] + hole_tilt[1]))
    draw = TrialDraw(hole, journal, body, grasp_offset, grasp_tilt, tip, vision_tilt,
                     (float(hole_vision[0] + platform[0]), float(hole_vision[1] + platform[1])))
    magnitude = {"clearance": hole - journal, "hole_vision": float(np.hypot(*hole_vision)),
                 "hole_tilt": float(np.hypot(*hole_tilt)), "platform": float(np.hypot(*platform)),
                 "inhand_tip": float(np.hypot(*tip)), "inhand_tilt": float(np.hypot(*tilt)),
                 "grasp_offset": abs(grasp_offset), "grasp_tilt": abs(grasp_tilt),
                 "tool_position": 0.0, "tool_tilt": 0.0}
    return TrialSample(draw, magnitude, float(np.hypot(*vision_tilt)))


PANDA = arm_model("panda")
PANDA_TABLE1 = transmission_errors(PANDA, "table1")
NOMINAL_TOOL = perturbed_poses(PANDA, ErrorSample(
    np.zeros((1, len(PANDA.lengths_m))), np.zeros((1, len(PANDA.q))), np.zeros((1, len(PANDA.q), 2)),
    np.zeros((1, len(PANDA.q))), np.zeros((1, len(PANDA.q), 2))))[0]
"""The Panda's tool pose at seed 001's working configuration without errors."""


def _seed001(rng: np.random.Generator, hole: float, journal: float, body: float,
             grasp_offset: float, grasp_tilt: float) -> TrialSample:
    """One robot of seed 001's analysis: the Panda with Table 1's errors; the tool's position
    error moves the journal off the hole, its orientation error tilts it (the guarded
    approach finds the surface whatever the height error)."""
    nominal = NOMINAL_TOOL
    pose = perturbed_poses(PANDA, sample_transmission(PANDA, PANDA_TABLE1, 1, rng))[0]
    dp = pose[:3, 3] - nominal[:3, 3]
    rel = pose[:3, :3] @ nominal[:3, :3].T
    tilt = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0]]) / 2  # small-angle x, y
    draw = TrialDraw(hole, journal, body, grasp_offset, grasp_tilt, (0.0, 0.0),
                     (float(tilt[0]), float(tilt[1])), (float(-dp[0]), float(-dp[1])))
    magnitude = {s: 0.0 for s in SOURCES} | {
        "clearance": hole - journal, "grasp_offset": abs(grasp_offset), "grasp_tilt": abs(grasp_tilt),
        "tool_position": float(np.hypot(dp[0], dp[1])), "tool_tilt": float(np.hypot(*tilt))}
    return TrialSample(draw, magnitude, float(np.hypot(*tilt)), float(np.linalg.norm(dp)))
