"""The benchmark's scenarios are what they claim to be (timings themselves are not asserted:
speed is the benchmark's job, not a test's)."""

from __future__ import annotations

import pytest

from serpar.checks.bench import BenchConfig, free_motion, in_contact
from serpar.errors import ConfigError


def test_contact_scenario_presses_the_journal_on_the_plate():
    report = in_contact(BenchConfig(sim_seconds=0.01, repeats=1, settle_s=0.5))
    assert report["push_n"] == pytest.approx(5.0, abs=0.5)  # the estimated push at 5 N demand
    assert report["replay_identical"]  # the floor is the loop's own trajectory
    assert 0 < report["gated_share"] <= 0.5  # the tray out once decided, the plate never (under the part)


def test_free_motion_floor_replays_the_loop_with_plate_and_tray_out():
    report = free_motion(BenchConfig(sim_seconds=0.05, repeats=1, settle_s=0.1))
    assert report["replay_identical"]
    assert report["gated_share"] > 0.8  # both out but for the first gate decision


def test_bad_bench_config():
    with pytest.raises(ConfigError, match="sim_seconds in 0.01..10"):
        BenchConfig(sim_seconds=100)
