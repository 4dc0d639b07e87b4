"""The five physical validation checks of the foundation issue, asserted at their limits."""

import pytest

from serpar.errors import UnknownNameError
from serpar.sim.physics import PhysicsConfig
from serpar.sim.validation import (
    CHECKS,
    check_aligned_insertion,
    check_lateral_penetration,
    check_rim_rest,
    check_stewart_loops,
    run_checks,
)

PHYSICS = PhysicsConfig()


def test_check1_offset_journal_rests_on_rim():
    r = check_rim_rest(PHYSICS)
    assert r.passed and r.value < 0.05  # depth [mm]


def test_check2_aligned_journal_reaches_full_depth_under_5N():
    r = check_aligned_insertion(PHYSICS)
    assert r.passed and r.value <= 0.001  # shortfall from 1.5 mm [mm]


def test_check3_lateral_load_penetration_below_one_micron():
    r = check_lateral_penetration(PHYSICS)
    assert r.passed and r.value <= 1.0  # [um]
    assert "20.0" in r.detail  # the load really was 20 N


def test_check5_stewart_loops_hold():
    r = check_stewart_loops(PHYSICS)
    assert r.passed and r.value <= 1.0  # [um]


def test_soft_contacts_fail_check3():
    """The check can fail: MuJoCo's default soft contact lets the journal sink into the wall."""
    soft = PhysicsConfig(precision_timeconst=0.02, precision_solimp=(0.9, 0.95, 1e-3, 0.5, 2.0))
    r = check_lateral_penetration(soft)
    assert not r.passed and r.value > 1.0


def test_unknown_check_lists_valid_names():
    with pytest.raises(UnknownNameError, match="valid: rim_rest"):
        run_checks(["nope"])
    assert list(CHECKS) == ["rim_rest", "aligned_insertion", "lateral_penetration", "noisy_stepping",
                            "stewart_loops"]
