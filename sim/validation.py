"""Physical validation checks (``serpar validate`` and the tests).

Each check measures one number and compares it with its limit. Users run these
after changing the timestep or contact settings.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from serpar.errors import UnknownNameError
from serpar.sim.loop_closure import loop_hold_and_stroke
from serpar.sim.physics import PhysicsConfig
from serpar.sim.rig import RigConfig, build_rig
from serpar.sim.scene_noise import NOISY_SCENES, step_with_noise
from serpar.sim.tolerances import HOLE_H7, JOURNAL_H6

# The widest H7/h6 pair (16 um diametral) is the worst case for jamming offsets and
# penetration; a tight pair (2 um) tests that nothing spurious blocks an aligned journal.
LOOSE = {"hole_diameter": HOLE_H7.max, "journal_diameter": JOURNAL_H6.min}
TIGHT = {"hole_diameter": HOLE_H7.min + 1e-6, "journal_diameter": JOURNAL_H6.max - 1e-6}


@dataclass(frozen=True)
class CheckResult:
    """One measured value against its limit."""

    name: str
    description: str
    value: float
    limit: float
    unit: str
    comparison: str
    """'<' or '<=' : how value must relate to limit."""
    detail: str = ""

    @property
    def passed(self) -> bool:
        if not math.isfinite(self.value):
            return False
        return self.value < self.limit if self.comparison == "<" else self.value <= self.limit

    def as_dict(self) -> dict:
        return {**asdict(self), "passed": self.passed}


def _press(rig, seconds: float, force: float) -> tuple[float, float]:
    """Press down with `force` for `seconds`; returns (final depth, max penetration) [m]."""
    m, d = rig.model, rig.data
    d.ctrl[2] = force
    worst = 0.0
    for _ in range(round(seconds / m.opt.timestep)):
        mujoco.mj_step(m, d)
        worst = max(worst, rig.max_penetration())
    return rig.depth(), worst


def check_rim_rest(physics: PhysicsConfig) -> CheckResult:
    """1. A journal offset beyond clearance + chamfer capture, pressed with 10 N, rests on the rim."""
    rig = build_rig(RigConfig(**LOOSE), physics)
    offset = rig.config.capture_radius + 5e-5
    rig.place(offset, 2e-4)
    depth, _ = _press(rig, 0.3, 10.0)
    return CheckResult("rim_rest", "offset journal pressed with 10 N stays on the rim: depth",
                       depth * 1e3, 0.05, "mm", "<",
                       f"offset {offset * 1e3:.3f} mm > capture {rig.config.capture_radius * 1e3:.3f} mm "
                       f"(radial clearance {rig.config.radial_clearance * 1e6:.1f} um + chamfers)")


def check_aligned_insertion(physics: PhysicsConfig) -> CheckResult:
    """2. An aligned journal (within the clearance) reaches full depth under <= 5 N."""
    shortfalls = []
    for pair in (TIGHT, LOOSE):
        rig = build_rig(RigConfig(**pair), physics)
        rig.place(0.5 * rig.config.radial_clearance, 2e-4)
        depth, _ = _press(rig, 0.3, 5.0)
        shortfalls.append(rig.config.conductor.journal_length - depth)
    worst = max(shortfalls)
    return CheckResult("aligned_insertion", "aligned journal pressed with 5 N: shortfall from full depth",
                       worst * 1e3, 0.001, "mm", "<=",
                       "tight (2 um) and loose (16 um) pairs; full depth 1.5 mm = shoulder seated")


def check_lateral_penetration(physics: PhysicsConfig) -> CheckResult:
    """3. Under a 20 N lateral contact load inside the bore, deepest penetration <= 1 um."""
    rig = build_rig(RigConfig(**LOOSE), physics)
    m, d = rig.model, rig.data
    rig.place(0.0, -1.0e-3)  # 1 mm into the bore
    wall = rig.config.radial_clearance
    stiffness = rig.config.lateral_stiffness
    dt = m.opt.timestep
    ramp, hold = 0.02, 0.1
    worst, force = 0.0, np.zeros(3)
    for i in range(round((ramp + hold) / dt)):
        load = 20.0 * min(1.0, i * dt / ramp)  # smooth ramp: a static load, not an impact
        d.ctrl[0] = wall + load / stiffness
        mujoco.mj_step(m, d)
        if i * dt >= ramp:
            worst = max(worst, rig.max_penetration())
            force = rig.contact_force()
    return CheckResult("lateral_penetration", "20 N lateral load in the bore: deepest penetration",
                       worst * 1e6, 1.0, "um", "<=",
                       f"measured lateral contact force {abs(force[0]):.2f} N")


def check_noisy_stepping(physics: PhysicsConfig) -> CheckResult:
    """4. Every scene stepped 2 s with random actuator noise: no MuJoCo warning, no NaN."""
    problems, total = [], 0
    for name in NOISY_SCENES:
        issues = step_with_noise(name, physics, seconds=2.0, seed=0)
        total += len(issues)
        problems += [f"{name}: {p}" for p in issues]
    return CheckResult("noisy_stepping", "scenes stepped 2 s with noisy control: warnings + NaNs",
                       float(total), 0.0, "count", "<=",
                       "; ".join(problems) if problems else f"scenes: {', '.join(NOISY_SCENES)}")


def check_stewart_loops(physics: PhysicsConfig) -> CheckResult:
    """5. Stewart closed loops hold: violation <= 1 um at rest and during a full-stroke motion."""
    rest, motion = loop_hold_and_stroke(physics)
    return CheckResult("stewart_loops", "Stewart loop-closure error, max of rest and full stroke",
                       max(rest, motion) * 1e6, 1.0, "um", "<=",
                       f"rest {rest * 1e6:.4f} um, full-stroke motion {motion * 1e6:.4f} um")


CHECKS: dict[str, Callable[[PhysicsConfig], CheckResult]] = {
    "rim_rest": check_rim_rest,
    "aligned_insertion": check_aligned_insertion,
    "lateral_penetration": check_lateral_penetration,
    "noisy_stepping": check_noisy_stepping,
    "stewart_loops": check_stewart_loops,
}


def run_checks(names: list[str] | None = None, physics: PhysicsConfig = PhysicsConfig(),
               progress: Callable[[str], None] | None = None) -> list[CheckResult]:
    """Run the named checks (all by default) in order."""
    selected = names or list(CHECKS)
    for n in selected:
        if n not in CHECKS:
            raise UnknownNameError("check", n, list(CHECKS))
    results = []
    for n in selected:
        if progress:
            progress(n)
        results.append(CHECKS[n](physics))
    return results
