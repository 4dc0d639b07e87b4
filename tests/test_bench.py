"""The benchmark's scenarios are what they claim to be (timings themselves are not asserted:
speed is the benchmark's job, not a test's)."""

from __future__ import annotations

import pytest

from serpar.checks.bench import BenchConfig, in_contact
from serpar.errors import ConfigError


def test_contact_scenario_presses_the_journal_on_the_plate():
    report = in_contact(BenchConfig(sim_seconds=0.01, repeats=1, settle_s=0.5))
    assert report["push_n"] == pytest.approx(5.0, abs=0.5)  # the estimated push at 5 N demand
    assert report["overhead"] > 0


def test_bad_bench_config():
    with pytest.raises(ConfigError, match="sim_seconds in 0.01..10"):
        BenchConfig(sim_seconds=100)
