"""The paper's argument as a seeded, CI-sized regression (issue 5): on seed 0's two far corner
holes, the serial robot alone misses (its friction-limited arm stops 0.3-0.4 mm off the hole),
while the Stewart correction through the model identified by a simulated motion-capture
campaign fills both with direct force-position control, the platform keeping the hole under
the journal as the arm's encoders see it wander on the way down (the nominal model misses hole 35 by
0.36 mm: measured, not asserted here, to keep the suite short).

The camera calibration is the session fixtures' (conftest); the Stewart campaign (60 poses,
~1.5 min) runs once for the module into a temporary file.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from serpar.checks.ablation import ablation_arms
from serpar.sim import names
from serpar.sim.seat_lock import PLATE_BODY, is_locked
from serpar.tasks.episode import build_runtime, run_episode
from serpar.tasks.episode_config import EpisodeConfig, Outcome
from serpar.tasks.platform_model import campaign_file

pytestmark = [pytest.mark.xdist_group("calibrated"), pytest.mark.slow]

BASE = EpisodeConfig(seed=0, holes=(0, 35))
"""Opposite corners of the grid: the platform moves ~35 mm from home, where the nominal
model's error is largest."""


@pytest.fixture(scope="module")
def pairs(calibrated_top, calibrated_inspect):
    return {"top": calibrated_top.calibration.pair, "inspect": calibrated_inspect.calibration.pair}


@pytest.fixture(scope="module")
def arms(tmp_path_factory):
    """The arms, with the calibrated ones' campaign run now into a fresh cache folder."""
    arms = {arm.name: arm.config for arm in ablation_arms(BASE)}
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SERPAR_CACHE", str(tmp_path_factory.mktemp("cache")))
        path = campaign_file(arms["Stewart, calibrated model"])
    assert path.is_file()
    return {name: dataclasses.replace(cfg, stewart_calibration=str(path)) if cfg.stewart_calibration == "campaign"
            else cfg for name, cfg in arms.items()}


def _holes(cfg: EpisodeConfig, pairs) -> list:
    records: list = []
    run_episode(cfg, pairs, on_record=records.append)
    return records


@pytest.fixture(scope="module")
def serial(arms, pairs):
    return _holes(arms["serial robot alone"], pairs)


class SeatedDrift:
    """Observer: how far each locked (seated, scored) part's tip strays, in the plate frame,
    from where it was in the last control period before its lock, while later holes are filled
    (a wrong pose at the lock would show as a jump)."""

    def __init__(self, rt) -> None:
        self.rt, self.free_at, self.locked_at, self.worst = rt, {}, {}, {}

    def __call__(self, rt) -> None:
        m, d = rt.scene.model, rt.scene.data
        plate = m.body(PLATE_BODY).id
        for k in range(len(rt.scene.conductor_bodies)):
            tip = m.site(f"{names.conductor(k)}tip").id
            at = (d.site_xpos[tip] - d.xpos[plate]) @ d.xmat[plate].reshape(3, 3)
            if not is_locked(rt.scene, k):
                self.free_at[k] = at.copy()
                continue
            start = self.locked_at.setdefault(k, self.free_at[k])
            self.worst[k] = max(self.worst.get(k, 0.0), float(np.linalg.norm(at - start)))


@pytest.fixture(scope="module")
def calibrated_run(arms, pairs):
    cfg = arms["Stewart, calibrated model"]
    rt, plate = build_runtime(cfg)
    drift = SeatedDrift(rt)
    rt.observers.append(drift)
    records: list = []
    run_episode(cfg, pairs, on_record=records.append, runtime=(rt, plate))
    return records, drift


@pytest.fixture(scope="module")
def calibrated(calibrated_run):
    return calibrated_run[0]


def test_a_seated_part_stays_put_while_the_next_hole_is_filled(calibrated_run):
    """Hole 0's part becomes part of the plate once scored (serpar.sim.seat_lock): it must not jump at
    the lock, nor move while the platform carries it ~35 mm to present hole 35 and back."""
    records, drift = calibrated_run
    assert records[0].outcome == Outcome.SUCCESS.value
    assert 0 in drift.worst, "the scored part was not locked"
    assert drift.worst[0] < 0.5e-6, f"{drift.worst[0] * 1e6:.3f} um"


def test_serial_robot_alone_misses_most_holes(serial):
    missed = [r for r in serial if r.outcome != Outcome.SUCCESS.value]
    assert len(missed) > len(serial) / 2, [r.reason for r in serial]
    assert all(r.outcome == Outcome.ALIGN_FAIL.value for r in missed)
    # The cause is the arm's positioning (friction against its impedance), not vision: the tip
    # lands beyond the ~0.2 mm capture of the two chamfers, not a few hundredths off.
    assert min(r.lateral_misalignment_mm for r in missed) > 0.25


def test_calibrated_stewart_correction_fills_the_near_corner_and_beats_the_arm(serial, calibrated):
    assert [r.hole for r in calibrated] == [0, 35]
    first = calibrated[0]
    assert first.outcome == Outcome.SUCCESS.value, first.reason
    assert first.depth_shortfall_mm < 0.02 and first.peak_force_n < 20.0
    for arm_alone, corrected in zip(serial, calibrated):  # closer to the axis at every hole
        assert corrected.lateral_misalignment_mm < 0.6 * arm_alone.lateral_misalignment_mm


def test_calibrated_force_position_fills_every_hole(calibrated):
    assert all(r.outcome == Outcome.SUCCESS.value for r in calibrated), [r.reason for r in calibrated]
    assert all(r.peak_force_n < 20.0 and r.depth_shortfall_mm < 0.02 for r in calibrated)


def test_calibrated_meets_every_hole_within_a_tenth(calibrated):
    """Issue 5's shortfall (hole 35 met ~0.12 mm off axis) was mostly the ~50 um the part slid in
    the pads between the in-hand inspection and the hover; with the pads' friction damping of
    issue 27 (tests/test_grasp.py) that slip is ~12x smaller; what is left is mostly the
    identified model's 30-60 um."""
    assert max(r.lateral_misalignment_mm for r in calibrated) < 0.1
